"""Concealed-effect recordings for the discovery benchmark, made the way ``kinemaforge demo``
makes its recording: the catalogue case's object and effects simulated in MuJoCo (the
independent ground truth), hand strokes that stay inside the joint range (the case's own plan
if it has one), sampled at 30 Hz
with 2 mrad (or 2 mm) Gaussian encoder noise and the hand's generalised force as ``tau``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.recording import Recording
from ..model.articulated import ArticulatedModel
from ..synth.effects import ConcealedEffect

RATE_HZ = 30
NOISE = 2e-3  # encoder noise std [rad or m]


@dataclass(frozen=True)
class EffectRecording:
    """A case's nominal ``model``, noisy ``recording``, the concealed ``effects`` and whether
    each concealed limit stop was reached by the true motion (``stop_reached``)."""

    case: str
    model: ArticulatedModel
    recording: Recording
    effects: tuple[ConcealedEffect, ...]
    stop_reached: bool

    @property
    def shown_effects(self) -> tuple[ConcealedEffect, ...]:
        """The concealed effects the motion shows: a limit contact only if its stop was reached."""
        return tuple(e for e in self.effects if e.type != "limit_contact" or self.stop_reached)


def stroke_plan():
    """Two strokes (to 50 % and back to 30 % of the range), each released and left free, so the
    held-out last quarter still contains motion."""
    from ..synth.groundtruth import HandPlan

    return HandPlan(goals=(0.5, 0.3), push_s=0.8, free_s=1.7, release_speed=0.15)


def effect_recording(case_name: str, noise_seed: int = 0, rate_hz: int = RATE_HZ) -> EffectRecording:
    """Simulate catalogue case ``case_name`` and return its noisy joint-space recording.  A case
    that defines its own hand plan (not the default ``HandPlan()``) is recorded with it, the
    others with :func:`stroke_plan`."""
    from problems.catalogue import get_case

    from ..synth.groundtruth import HandPlan, simulate
    from ..synth.objects import make_object

    case = get_case(case_name)
    obj = make_object(case.category, case.seed)
    plan = case.plan if case.plan != HandPlan() else stroke_plan()
    ep = simulate(obj.model, obj.handles, case.effects, plan=plan, record_hz=rate_hz)
    rng = np.random.default_rng(noise_seed)
    q = ep.q + rng.normal(0.0, NOISE, ep.q.shape)
    reached = False
    for e in case.effects:
        if e.type == "limit_contact":
            k = ep.joint_names.index(e.joint)
            beyond = ep.q[:, k] > e.value if e.param("side") == "upper" else ep.q[:, k] < e.value
            reached = reached or bool(beyond.any())
    return EffectRecording(case_name, obj.model, Recording(ep.t, ep.joint_names, q, tau=ep.tau), case.effects, reached)
