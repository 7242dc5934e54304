"""Concealed-effect recordings for the discovery benchmark, made the way ``kinemaforge demo``
makes its recording: the catalogue case's object and effects simulated in MuJoCo (the
independent ground truth), hand strokes that stay inside the joint range (the case's own plan
if it has one), sampled at 30 Hz
with 2 mrad (or 2 mm) Gaussian encoder noise and the hand's generalised force as ``tau``.

Each case also has a second, independent recording (:func:`other_recording`): the same true
system driven by a different hand plan (:func:`heldout_plan`) with its own noise draw.  It is
never shown to a method; it scores the prediction of what a method found on motion it did not
fit, forced and free (the last quarter of the fitted recording is mostly the free coast, where
an inertia error, a spring near its rest or an unreached stop leave no trace)."""

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


def heldout_plan(case_plan=None):
    """The hand plan of the held-out recording.  By default three strokes (to 75 %, back to 30 %,
    to 50 % of the range), slower than :func:`stroke_plan`'s, each released at a lower speed and
    left free for 1.2 s: the first passes the stops the catalogue conceals, none coasts into the
    joint's own limits.  A case with its own plan (``case_plan``, e.g. a slow push that dwells
    where Stribeck friction acts) is held out on that plan's timing with other goals (30 %, then
    50 % of the range), so the second recording exercises the same regime."""
    from dataclasses import replace

    from ..synth.groundtruth import HandPlan

    if case_plan is not None and case_plan != HandPlan():
        return replace(case_plan, goals=(0.3, 0.5))
    return HandPlan(goals=(0.75, 0.3, 0.5), push_s=1.2, free_s=1.2, release_speed=0.1)


OTHER_NOISE_OFFSET = 1000  # the held-out recording's noise seed: the case's seed + this


def other_recording(case_name: str, noise_seed: int = 0, rate_hz: int = RATE_HZ) -> EffectRecording:
    """The held-out recording of catalogue case ``case_name``: :func:`heldout_plan` on the same true
    system, with the noise stream ``noise_seed + OTHER_NOISE_OFFSET``."""
    from problems.catalogue import get_case

    return effect_recording(case_name, noise_seed + OTHER_NOISE_OFFSET, rate_hz,
                            plan=heldout_plan(get_case(case_name).plan))


def effect_recording(case_name: str, noise_seed: int = 0, rate_hz: int = RATE_HZ, plan=None) -> EffectRecording:
    """Simulate catalogue case ``case_name`` and return its noisy joint-space recording.  A case
    that defines its own hand plan (not the default ``HandPlan()``) is recorded with it, the
    others with :func:`stroke_plan`; ``plan`` (a ``HandPlan``) overrides both."""
    from problems.catalogue import get_case

    from ..synth.groundtruth import HandPlan, simulate
    from ..synth.objects import make_object

    case = get_case(case_name)
    obj = make_object(case.category, case.seed)
    if plan is None:
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
