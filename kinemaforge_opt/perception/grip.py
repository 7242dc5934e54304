"""The recorded push's grip as a tracking cue.

A wrench row is a force at a world point p (DESIGN.md, ``wrenches.csv``).  Over one contact
(:meth:`~kinemaforge_opt.io.sequence.Wrenches.contacts`) a hand that holds a part moves with it,
so between two frame times the point's displacement is that of the part's material point under
the hand.  A drawer pulled from rest 13 cm between two samples is beyond ICP's reach from its rest
pose (:mod:`.track`); moved by the grip's displacement it starts on the pulled front.  For a part
that turns, the translation is the grip point's only, a first-order guess that ICP completes.  A
push that slides along a surface is no grip: the guess is then wrong, and the free-space
verification and the fit ranking (:meth:`~.track.Tracker.solve_step`) drop it as they drop any
other start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.sequence import Wrenches


@dataclass(frozen=True, eq=False)
class GripPath:
    """The wrench point over each contact: runs of (t (k,) [s], p (k, 3) world [m]), k ≥ 2."""

    runs: tuple[tuple[np.ndarray, np.ndarray], ...]

    @classmethod
    def of(cls, wrenches: Wrenches | None) -> GripPath | None:
        """The contacts of ``wrenches`` that last more than one row, or None without any."""
        if wrenches is None:
            return None
        runs = tuple((np.asarray(wrenches.t[a : b + 1], dtype=float), np.asarray(wrenches.points_world[a : b + 1], dtype=float))
                     for a, b in wrenches.contacts() if b > a)
        return cls(runs) if runs else None

    def move(self, t_from: float, t_to: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Where the grip meets the span between ``t_from`` and ``t_to`` [s] (either order) and how
        far it moves over it: (point (3,) [m], displacement (3,) [m]).  The point is the first
        overlapping contact's, at the end of its overlap nearest ``t_from`` (where the part is
        when the hand's pull starts to count); the displacement is summed over every overlapping
        contact, from ``t_from``'s side to ``t_to``'s.  None when no contact overlaps the span."""
        lo, hi = min(t_from, t_to), max(t_from, t_to)
        forward = t_to >= t_from
        moves = []
        for t, p in self.runs:
            a, b = max(lo, t[0]), min(hi, t[-1])
            if a >= b:
                continue
            start, end = (a, b) if forward else (b, a)
            at = lambda x: np.array([np.interp(x, t, p[:, i]) for i in range(3)])  # noqa: E731
            moves.append((abs(start - t_from), at(start), at(end) - at(start)))
        if not moves:
            return None
        moves.sort(key=lambda m: m[0])
        return moves[0][1], np.sum([m[2] for m in moves], axis=0)
