"""Colour decides the pixels where an object meets the floor (perception.colour).

A synthetic image: a floor of two-tone tiles and a box standing on it; the kept pixels lie on a
grid of step 2.  The depth-only labels put the box's bottom strip (three grid rows) in the
environment, as the floor's plane band does on rendered episodes."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.perception.colour import relabel_contact_by_colour

ENV = "environment"
H, W, STRIDE = 120, 160, 2
BOX_ROWS, BOX_COLS = (40, 90), (50, 110)


def _scene(box_rgb, seed=0):
    """(rgb image, kept pixels (N, 2), true labels (N,)) with a 'box' on tiled floor."""
    rows, cols = np.mgrid[0:H, 0:W]
    tile = ((rows // 40) + (cols // 40)) % 2
    rgb = np.where(tile[..., None] == 1, [150, 140, 120], [95, 90, 80]).astype(float)
    box = (rows >= BOX_ROWS[0]) & (rows < BOX_ROWS[1]) & (cols >= BOX_COLS[0]) & (cols < BOX_COLS[1])
    rgb[box] = box_rgb
    rgb = np.clip(rgb + np.random.default_rng(seed).normal(0.0, 3.0, rgb.shape), 0, 255).astype(np.uint8)
    pixels = np.stack([rows[::STRIDE, ::STRIDE].ravel(), cols[::STRIDE, ::STRIDE].ravel()], axis=1)
    truth = np.where(box[pixels[:, 0], pixels[:, 1]], "box", ENV).astype(object)
    return rgb, pixels, truth


def _depth_only(pixels, truth):
    """The true labels with the box's bottom three grid rows (6 px) given to the environment."""
    labels = truth.copy()
    strip = (truth == "box") & (pixels[:, 0] >= BOX_ROWS[1] - 3 * STRIDE)
    labels[strip] = ENV
    return labels, strip


def test_the_bottom_strip_goes_back_to_the_object_and_no_floor_pixel_leaves_the_floor():
    rgb, pixels, truth = _scene([70, 80, 160])
    labels, strip = _depth_only(pixels, truth)
    out = relabel_contact_by_colour(pixels, labels, STRIDE, rgb, ENV)
    assert np.all(out[strip] == "box"), f"{np.mean(out[strip] == 'box'):.2f} of the strip recovered"
    assert np.all(out[truth == ENV] == ENV)
    assert np.all(labels[strip] == ENV), "the input labels must not change"


def test_the_strip_takes_the_label_of_the_object_pixels_next_to_it():
    rgb, pixels, truth = _scene([70, 80, 160])
    truth[(truth == "box") & (pixels[:, 1] >= 80)] = "door"  # the right half is a part
    labels, strip = _depth_only(pixels, truth)
    out = relabel_contact_by_colour(pixels, labels, STRIDE, rgb, ENV)
    inner = strip & (np.abs(pixels[:, 1] - 80) > 2 * STRIDE)  # away from the seam
    assert np.all(out[inner] == truth[inner])


def test_an_object_painted_like_its_floor_keeps_the_depth_only_labels_on_the_floor():
    rgb, pixels, truth = _scene([150, 140, 120])  # the light tile's colour
    labels, _ = _depth_only(pixels, truth)
    out = relabel_contact_by_colour(pixels, labels, STRIDE, rgb, ENV)
    assert np.all(out[truth == ENV] == ENV)


def test_an_image_with_no_object_label_is_returned_as_it_is():
    rgb, pixels, _ = _scene([70, 80, 160])
    labels = np.full(len(pixels), ENV, dtype=object)
    assert np.all(relabel_contact_by_colour(pixels, labels, STRIDE, rgb, ENV) == ENV)
