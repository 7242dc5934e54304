"""Which screw the observed points support (nlp.screw_type): exact worlds whose true joint is known,
each candidate type's closed form scored on the points, BIC over the line parameters."""

from __future__ import annotations

import numpy as np

from kinemaforge_opt.nlp.screw_type import SCREW_PARAMETERS, closed_form_fit, simplest_supported

from .worlds import BOX, door_model, exact_data

ORIGIN = np.array([0.3, 0.2, 0.1])
TIMES = np.linspace(0.0, 1.0, 6)
PAIRS = 200


def _fits(true, candidates: dict) -> dict:
    """{type: closed_form_fit} for candidate (model, q_init) pairs on the exact points of ``true``
    moving as candidates['true q']."""
    q_true = candidates.pop("true q")
    return {kind: closed_form_fit(exact_data(true, model, TIMES, q_true, q), PAIRS) for kind, (model, q) in candidates.items()}


def test_a_true_helix_is_kept():
    axis, pitch = np.array([0.0, 0.0, 1.0]), 0.05  # 5 cm per radian
    true = door_model(axis, ORIGIN, kind="helical", pitch=pitch)
    q = 0.8 * TIMES
    fits = _fits(true, {"true q": q,
                        "helical": (true, q),
                        "revolute": (door_model(axis, ORIGIN, kind="revolute"), q),  # the turn, not the rise
                        "prismatic": (door_model(axis, ORIGIN, kind="prismatic"), pitch * q)})  # the rise alone
    assert simplest_supported(fits) == "helical"
    assert fits["helical"][0] < 0.5 * min(fits["revolute"][0], fits["prismatic"][0])


def test_a_slide_whose_track_turned_is_a_slide():
    # a drawer front pulled 0.3 m out along its face normal; the helix a turning track gives:
    # the same line through the front's centre, turning 5 degrees over the pull
    out = np.array([0.0, -1.0, 0.0])
    true = door_model(out, ORIGIN, kind="prismatic")
    travel = 0.3 * TIMES
    pitch = 0.3 / np.deg2rad(5.0)  # [m/rad]
    centre = ORIGIN + np.array([BOX[0] / 2 + 0.01, 0.0, 0.0])
    helix = door_model(out, centre, kind="helical", pitch=pitch, body_origin=ORIGIN)
    fits = _fits(true, {"true q": travel, "prismatic": (true, travel), "helical": (helix, travel / pitch)})
    assert simplest_supported(fits) == "prismatic"


def test_bic_prices_each_added_parameter_and_ties_go_to_the_simpler_type():
    n = 1000
    price = 0.5 * np.log(n)  # ½ ln n per parameter, in ½χ² units
    extra = SCREW_PARAMETERS["helical"] - SCREW_PARAMETERS["prismatic"]
    assert simplest_supported({"helical": (100.0, n), "prismatic": (100.0 + 0.99 * extra * price, n)}) == "prismatic"
    assert simplest_supported({"helical": (100.0, n), "prismatic": (100.0 + 1.01 * extra * price, n)}) == "helical"
    assert simplest_supported({"revolute": (5.0, n), "prismatic": (5.0 + 2 * price, n)}) == "prismatic"  # a tie
