"""A D435-like RGB-D sensor model applied to ideal renders.

Depth: Gaussian noise with σ = ``depth_sigma_k``·z² (stereo disparity noise), dropouts at depth
discontinuities and at grazing incidence, sparse random dropouts, a valid range, and
quantisation to ``depth_quantum`` (1 mm).  RGB: additive Gaussian noise, then 8-bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorModel:
    """Noise parameters.

    depth_sigma_k: σ_z = k·z² [1/m] (D435 at 848×480: about 0.002–0.004).
    edge_dropout: probability of losing a pixel whose 4-neighbourhood spans a depth jump larger
    than ``edge_jump`` × z.  grazing_deg: incidence angle [deg] beyond which pixels drop out
    (probability ramps from 0 at grazing_deg to 1 at 90°).  random_dropout: probability per pixel.
    min_range_m, max_range_m: valid depth range [m].  depth_quantum: depth resolution [m].
    rgb_sigma: RGB noise σ on a 0–1 scale.
    """

    depth_sigma_k: float = 0.003
    edge_dropout: float = 0.6
    edge_jump: float = 0.03
    grazing_deg: float = 75.0
    random_dropout: float = 0.002
    min_range_m: float = 0.2
    max_range_m: float = 6.0
    depth_quantum: float = 0.001
    rgb_sigma: float = 0.01


D435 = SensorModel()
CLEAN = SensorModel(depth_sigma_k=0.0, edge_dropout=0.0, grazing_deg=90.0, random_dropout=0.0,
                    min_range_m=0.0, max_range_m=60.0, rgb_sigma=0.0)


def noisy_depth(depth: np.ndarray, cos_incidence: np.ndarray, sensor: SensorModel, rng: np.random.Generator) -> np.ndarray:
    """Apply the depth model.

    depth: (H, W) ideal z-depth [m], 0 where nothing was hit.  cos_incidence: (H, W) |cos| of the
    angle between the viewing ray and the surface normal.  Returns (H, W) depth [m] quantised to
    ``sensor.depth_quantum``, 0 = no reading.
    """
    z = np.asarray(depth, dtype=float)
    valid = z > 0
    out = z + rng.standard_normal(z.shape) * sensor.depth_sigma_k * z**2
    pad = np.pad(z, 1, mode="edge")
    jump = np.max(np.abs(np.stack([pad[:-2, 1:-1], pad[2:, 1:-1], pad[1:-1, :-2], pad[1:-1, 2:]]) - z), axis=0)
    edge = valid & (jump > sensor.edge_jump * np.maximum(z, 1e-6))
    drop = edge & (rng.random(z.shape) < sensor.edge_dropout)
    if sensor.grazing_deg < 90.0:
        angle = np.degrees(np.arccos(np.clip(cos_incidence, 0.0, 1.0)))
        p_graze = np.clip((angle - sensor.grazing_deg) / (90.0 - sensor.grazing_deg), 0.0, 1.0)
        drop |= rng.random(z.shape) < p_graze
    drop |= rng.random(z.shape) < sensor.random_dropout
    out[~valid | drop | (out < sensor.min_range_m) | (out > sensor.max_range_m)] = 0.0
    return np.round(out / sensor.depth_quantum) * sensor.depth_quantum


def noisy_rgb(rgb: np.ndarray, sensor: SensorModel, rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) RGB in [0, 1] -> (H, W, 3) uint8 with additive Gaussian noise."""
    noisy = np.asarray(rgb, dtype=float) + rng.standard_normal(np.shape(rgb)) * sensor.rgb_sigma
    return np.clip(np.round(noisy * 255.0), 0, 255).astype(np.uint8)
