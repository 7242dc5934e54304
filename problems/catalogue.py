"""The benchmark catalogue: ``CASES`` maps a name to a frozen :class:`~kinemaforge_opt.synth.case.Case`.

Groups (the name prefix says which):

* ``protocol_<category>_<n>`` — the seed protocol: 5 categories × N = 2 instances, 8 static
  calibrated views per articulation state, 640×480, D435-like noise, no concealed effects
  (kinematics only), plus ``protocol_cabinet_multi_<n>`` and one moving-camera case.
* ``effect_<joint kind>_<effect>`` — the concealed-effects set: each effect alone on a hinged door
  (``door``) and on a drawer (``drawer``), a few pairs, and null cases (``null_…``).  Two
  views at 320×240: these cases are mainly for the joint-space entry (recording.csv + model.urdf).
* ``tiny_…`` — small cases for tests (64×48 px, 2 views, few frames).
* ``timing_episode`` — the generation-speed figure: a 10-s episode rendered at 30 Hz from 4
  views at 640×480 (``python -m problems.time_synth`` times it).

Seeds are fixed, so every case reproduces bit-for-bit on one machine.
"""

from __future__ import annotations

from kinemaforge_opt.errors import UnknownNameError
from kinemaforge_opt.synth.case import Case
from kinemaforge_opt.synth.effects import ConcealedEffect as E
from kinemaforge_opt.synth.groundtruth import HandPlan
from kinemaforge_opt.synth.sensor import CLEAN

PROTOCOL_CATEGORIES = ("cabinet", "drawer", "laptop", "refrigerator", "microwave")
PROTOCOL_INSTANCES = 2  # N per category: small enough for a 2-core machine
PROTOCOL_VIEWS = 8

DOOR = ("cabinet", 0, "door_joint")  # single left/right-hinged door, about 6 kg, 0.5 kg·m²
DRAWER = ("drawer", 0, "drawer_0_joint")  # one drawer, about 5 kg

# Realistic magnitudes per joint kind: (value, params)
_DOOR_EFFECTS = {
    "viscous_damping": (0.8, ()),
    "coulomb_friction": (0.4, ()),
    "stribeck_friction": (0.5, (("v_stribeck", 0.1),)),
    "spring": (3.0, (("rest", 0.3),)),
    "constant_bias": (-0.5, ()),
    "axis_tilt": (0.035, (("azimuth", 0.7),)),
    "inertia_error": (1.4, ()),
    "quadratic_drag": (0.6, ()),
    "limit_contact": (1.2, (("stiffness", 60.0), ("side", "upper"))),
}
_DRAWER_EFFECTS = {
    "viscous_damping": (8.0, ()),
    "coulomb_friction": (3.0, ()),
    "stribeck_friction": (3.0, (("v_stribeck", 0.02),)),
    "spring": (40.0, (("rest", 0.05),)),
    "constant_bias": (-2.0, ()),
    "axis_tilt": (0.03, (("azimuth", 0.0),)),
    "inertia_error": (1.5, ()),
    "quadratic_drag": (30.0, ()),
    "limit_contact": (0.2, (("stiffness", 5000.0), ("side", "upper"))),
}
_PAIRS = {
    "door": (("coulomb_friction", "viscous_damping"), ("spring", "coulomb_friction"),
             ("axis_tilt", "viscous_damping"), ("inertia_error", "quadratic_drag")),
    "drawer": (("coulomb_friction", "viscous_damping"), ("stribeck_friction", "coulomb_friction")),
}


# A slow stroke to 15 % of the range, then one to 60 % (3 s push, 1 s free each; 8 s).
SLOW_PUSH = HandPlan(goals=(0.15, 0.6), push_s=3.0, free_s=1.0, release_speed=0.15)


def _effect(kind: str, joint: str, etype: str) -> E:
    value, params = (_DOOR_EFFECTS if kind == "door" else _DRAWER_EFFECTS)[etype]
    return E(etype, joint, value, params)


def _expect(effects: tuple[E, ...]) -> str:
    if not effects:
        return "null case: diagnose reports no effect; calibrated dynamics stay near zero"
    parts = [f"{e.type}={e.value:g} on {e.joint}" + (f" ({', '.join(f'{k}={v}' for k, v in e.params)})" if e.params else "")
             for e in effects]
    return "diagnose reports " + " and ".join(parts) + " (value within 15%, or 0.3° for axis_tilt), and nothing else"


def _effect_cases() -> dict[str, Case]:
    out = {}
    for kind, (category, seed, joint) in (("door", DOOR), ("drawer", DRAWER)):
        common = dict(category=category, seed=seed, views=2, frames=24, width=320, height=240)
        for etype in _DOOR_EFFECTS:
            effects = (_effect(kind, joint, etype),)
            out[f"effect_{kind}_{etype}"] = Case(f"effect_{kind}_{etype}", effects=effects, expected=_expect(effects), **common)
        for a, b in _PAIRS[kind]:
            effects = (_effect(kind, joint, a), _effect(kind, joint, b))
            name = f"effect_{kind}_{a}+{b}"
            out[name] = Case(name, effects=effects, expected=_expect(effects), **common)
        # Stribeck friction acts only below a few v_stribeck: the two quick strokes above pass
        # through that regime in a fraction of a second.  This case pushes slowly first (about
        # v_stribeck for 3 s), then faster (about 3-4x v_stribeck), so the recording both dwells
        # where the effect acts and shows that it fades with speed.
        effects = (_effect(kind, joint, "stribeck_friction"),)
        name = f"effect_{kind}_stribeck_friction_slow_push"
        out[name] = Case(name, effects=effects, expected=_expect(effects), plan=SLOW_PUSH, **common)
        out[f"null_{kind}"] = Case(f"null_{kind}", expected=_expect(()), **common)
    out["null_laptop"] = Case("null_laptop", "laptop", 0, views=2, frames=24, width=320, height=240, expected=_expect(()))
    return out


_KINEMATICS = "reconstruct recovers every joint's type, axis within 2° and origin within 2 cm, part IoU > 0.8"


def _protocol_cases() -> dict[str, Case]:
    out = {}
    for category in PROTOCOL_CATEGORIES + ("cabinet_multi",):
        for n in range(PROTOCOL_INSTANCES):
            name = f"protocol_{category}_{n}"
            out[name] = Case(name, category, 100 + n, views=PROTOCOL_VIEWS, frames=20, expected=_KINEMATICS)
    out["protocol_moving_cabinet"] = Case("protocol_moving_cabinet", "cabinet", 100, views=1, frames=60,
                                          moving_camera=True, expected=_KINEMATICS + " from one moving camera")
    return out


def _tiny_cases() -> dict[str, Case]:
    small = dict(views=2, frames=4, width=64, height=48)
    door_damped = (E("viscous_damping", "door_joint", 0.8),)
    return {
        "tiny_door": Case("tiny_door", "cabinet", 0, door_damped, expected=_expect(door_damped), **small),
        "tiny_door_clean": Case("tiny_door_clean", "cabinet", 0, noise=CLEAN, expected=_expect(()), **small),
        "tiny_drawer": Case("tiny_drawer", "drawer", 0, expected=_expect(()), **small),
        "tiny_laptop": Case("tiny_laptop", "laptop", 0, expected=_expect(()), **small),
        "tiny_fridge": Case("tiny_fridge", "refrigerator", 0, expected=_expect(()), **small),
        "tiny_multi": Case("tiny_multi", "cabinet_multi", 0, expected=_expect(()), **small),
        "tiny_moving": Case("tiny_moving", "microwave", 0, views=1, frames=4, width=64, height=48,
                            moving_camera=True, expected=_expect(())),
    }


def _timing_cases() -> dict[str, Case]:
    # two doors, one 5-s stroke each: 10 s, 300 rendered time steps
    plan = HandPlan(goals=(0.6,), push_s=1.0, free_s=4.0)
    return {"timing_episode": Case("timing_episode", "cabinet", 100, views=4, frames=300, record_hz=30, plan=plan,
                                   expected=_KINEMATICS)}


CASES: dict[str, Case] = {**_protocol_cases(), **_effect_cases(), **_tiny_cases(), **_timing_cases()}


def get_case(name: str) -> Case:
    """The case called ``name``; raises :class:`UnknownNameError` listing the valid names."""
    if name not in CASES:
        raise UnknownNameError("benchmark case", name, CASES)
    return CASES[name]
