"""Which joint type the observed points support: a helix, or the simpler screw it may be.

The constraint graph types a joint from the part's pose track.  A track can turn where the part
does not: ICP on a drawer's flat front hardly sees a turn about the front's normal, and a
constant-velocity guess that wins its ties carries a small turn on (protocol_cabinet_multi_1: a
drawer's track turned 9.5° over a 0.3-m pull, and the graph, rightly on that track, fitted a
helix).  The points themselves decide here: each candidate type's closed-form motion moves the
part's zero-configuration surface onto its observed points, and the robust visual term of the
screw NLP (Σ ρ(r)/δ² ≈ ½ χ², :func:`~.reconstruction.vis_value`) says how well.  A richer type is
kept only when it fits better than a simpler one by more than BIC's price for the parameters it
adds, ½ Δk ln n (n: the point pairs).
"""

from __future__ import annotations

import numpy as np

from .reconstruction import ScrewData, correspondences, initial_state, vis_value

# Line parameters of each screw: a direction (2), a point on a rotation axis (2), a pitch (1).
SCREW_PARAMETERS = {"prismatic": 2, "revolute": 4, "helical": 5}


def closed_form_fit(data: ScrewData, points_per_part: int) -> tuple[float, int]:
    """(½ χ², n) of the closed-form motion in ``data`` (its model and q_init): the robust visual
    term over fresh correspondences of at most ``points_per_part`` observed points per part and
    step, and the number of point pairs it holds."""
    state = initial_state(data)
    pairs = correspondences(data, state, points_per_part)
    n = sum(int(np.count_nonzero(c.weights > 0)) for items in pairs.values() for c in items)
    return vis_value(data, state, pairs), n


def simplest_supported(fits: dict[str, tuple[float, int]]) -> str:
    """The type of ``fits`` ({type: (½ χ², n)}, types of :data:`SCREW_PARAMETERS`) that BIC prefers:
    ½ χ² + ½ k ln n, k the type's line parameters, with n the fewest pairs of any candidate (the
    same points, paired a little differently by each motion); ties go to the simpler type."""
    n = max(min(count for _, count in fits.values()), 2)
    score = {kind: half_chi2 + 0.5 * SCREW_PARAMETERS[kind] * np.log(n) for kind, (half_chi2, _) in fits.items()}
    return min(score, key=lambda kind: (score[kind], SCREW_PARAMETERS[kind]))
