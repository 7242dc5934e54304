"""The drift's range over ±1 % of each moving link's mass (verify.drift.drift_range): wide where
the motion is a knife edge, narrow where it is not.

The knife edge is built from the physics, not from the function: a laptop lid (the synthetic
world's) pushed from shut by a torque pulse just strong enough to carry it over its balance point
(where its weight's moment changes sign) falls open onto its stop; 1 % heavier, the same pulse
leaves it short of the balance point and it falls back shut.  A door on a plumb hinge has no
balance point: 1 % more or less mass changes its swing by about 1 %."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.model.pinocchio import build_pin_model
from kinemaforge_opt.synth.objects import make_object
from kinemaforge_opt.verify.drift import MASS_SHARE, drift, drift_range
from kinemaforge_opt.verify.simulate import simulate_at

T = np.arange(0.0, 4.0 + 1e-9, 1 / 30)  # 30 Hz [s]
PUSH_S = 0.4


def pulse(model, torque: float, t: np.ndarray = T) -> Recording:
    """A torque [N·m] held for PUSH_S on the joint of a one-joint model, then nothing."""
    return Recording(t, model.joint_names, np.zeros((t.size, 1)), tau=np.where(t < PUSH_S, torque, 0.0)[:, None])


def replayed(model, torque: float) -> Recording:
    """The model's own Drake motion under the pulse, as a recording (q, τ at 30 Hz)."""
    sim = simulate_at(model, np.zeros(1), np.zeros(1), T, pulse(model, torque))
    return Recording(T, model.joint_names, sim.q, tau=pulse(model, torque).tau)


def balance_angle(model) -> float:
    """Where the lid's weight's moment about its hinge changes sign [rad] (Pinocchio's gravity)."""
    pm = build_pin_model(model)
    data = pm.createData()
    j = model.movable_joints[0]
    qs = np.linspace(j.limits.lower, j.limits.upper, 400)
    g = np.array([pin.computeGeneralizedGravity(pm, data, np.array([q]))[0] for q in qs])
    (k,) = np.flatnonzero(np.sign(g[1:]) != np.sign(g[:-1]))
    return float(qs[k])


def test_a_lid_pushed_just_over_its_balance_point_is_a_knife_edge():
    model = make_object("laptop", 0).model
    top = balance_angle(model)
    t = T[T <= 2.5]

    def falls_open(torque: float) -> bool:
        return simulate_at(model, np.zeros(1), np.zeros(1), t, pulse(model, torque, t)).q[-1, 0] > top

    low, high = 0.0, 2.0  # N·m: not over / over
    assert not falls_open(low) and falls_open(high)
    for _ in range(14):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if falls_open(mid) else (mid, high)
    rec = replayed(model, high * 1.002)  # 0.2 % over the threshold: over the top, onto the open stop
    assert rec.q[-1, 0] > top
    nominal = drift(model, rec, (1.0, 3.0), v0=np.zeros(1)).drift_m
    spread = drift_range(model, rec, (1.0, 3.0), v0=np.zeros(1))
    assert np.all(nominal < 1e-3)  # the model replays its own motion
    least, largest = spread[1]
    assert least < 1e-3 and largest > 0.1  # 1 % heavier, the lid falls back shut: 0.21 m when written


def test_a_door_pushed_open_is_no_knife_edge():
    model = make_object("cabinet", 0).model
    rec = replayed(model, 2.0)
    assert rec.q[:, 0].max() > 0.3  # it swings well open
    spread = drift_range(model, rec, (1.0,), v0=np.zeros(1))
    swing = np.ptp(rec.q[T <= 1.0, 0]) * 0.4  # the door's reach [m] (0.4 m from the hinge, at least)
    assert spread[0, 1] < 2 * MASS_SHARE * swing  # about 1 % of its swing: 1.9 mm when written
