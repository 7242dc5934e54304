"""Nominal model vs classical IDIM-LS vs kinemaforge_opt on the two MuJoCo "real" Pandas.

Nominal model: the Panda URDF of example-robot-data.  "Real" robots (never seen by the
estimators): (a) that URDF with concealed inertia/armature/damping/friction changes, (b) the
independently authored Franka Kitchen Panda of gymnasium-robotics.

Protocol of :func:`compare_arm_models`: design a Fourier excitation (condition number of the base
regressor) -> drive each real arm along it with PD + feedforward, recording q, v and the applied
torque at 1 kHz with sensor noise -> fit IDIM-LS and ``calibrate(method="inverse_dynamics")``
(embedded with :func:`.embedding.embed`) on the first 75 % -> held-out torque RMS on the last
25 % and on a second, different trajectory -> computed-torque tracking RMS of the second
trajectory on the real arm with each model as the inverse dynamics.  Used by
``examples/04_arm_calibration.py`` and ``kinemaforge bench``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from ..calibration import calibrate
from ..io.recording import write_recording
from .control import inverse_dynamics, track
from .embedding import embed
from .excitation import design_excitation, excitation_plan, model_limits, random_fourier
from .idim import batched, fit_idim_ls, held_out_rms
from .mujoco_real import SensorNoise, concealed_panda, kitchen_panda, record_plan
from .panda import load_panda

KP = np.array([600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0])  # recording PD gains [N·m/rad]
KD = np.array([50.0, 50.0, 50.0, 20.0, 20.0, 20.0, 10.0])  # [N·m·s/rad]
CT_KP, CT_KD = 100.0, 20.0  # computed-torque outer loop [1/s², 1/s]
HELD_OUT_FRACTION = 0.25  # last part of the excitation kept out of the fits
MODELS = ("nominal", "IDIM-LS", "kinemaforge_opt")
HELD_OUT = ("excitation last 25%", "second trajectory")


def _rms_entry(r: np.ndarray) -> dict:
    return {"per_joint": [float(x) for x in r], "mean": float(np.mean(r))}


def compare_arm_models(quick: bool, out_dir: Path | None = None, progress=None) -> dict:
    """Run the side-by-side; returns a JSON-ready dict.

    quick: 6 s excitation / 5 s test trajectory and a 5-iteration excitation design (else 20 s /
    10 s and 40 iterations).  out_dir: if given, writes the plans, the recordings,
    ``tracking_error.png`` and ``heldout_torque.png`` there.  progress: optional ``f(str)``.

    Result keys: ``quick``, ``joints`` (n names), ``models`` (:data:`MODELS`), ``excitation``
    (``duration_s``, ``test_duration_s``, ``initial_condition`` / ``condition``: cond of the base
    regressor before / after the design, ``iterations``, ``design_time_s``), ``arms`` (per real
    arm name: ``fit_duration_s``, ``rate_hz``, ``fit_time_s`` per model [s] (None for nominal),
    ``idim_base_parameters``, ``ipopt_status``, ``ipopt_iterations``, ``identifiability`` (str),
    ``physically_consistent`` (bool, the identified inertias), ``friction`` (``viscous``
    [N·m·s/rad] / ``coulomb`` [N·m] -> IDIM-LS / kinemaforge_opt -> (n,) lists),
    ``heldout_torque_rms_nm`` (held-out set in :data:`HELD_OUT` -> model -> ``per_joint`` (n,) and
    ``mean`` [N·m]), ``tracking_rms_mrad`` (model -> ``per_joint`` (n,) and ``mean`` [mrad])) and
    ``total_s`` [s].

    Runs with one BLAS thread: its matrices are small (at most ~10⁴ rows × 98 columns), and
    threaded OpenBLAS on busy shared cores made the excitation design over 100× slower (0.5 s ->
    66 s measured on 2 cores with another process running)."""
    with threadpool_limits(limits=1, user_api="blas"):
        return _compare(quick, None if out_dir is None else Path(out_dir), progress or (lambda s: None))


def _compare(quick: bool, out_dir: Path | None, say) -> dict:
    """:func:`compare_arm_models` without the thread limit; say: ``f(str)``."""
    t_start = time.perf_counter()
    duration, test_duration = (6.0, 5.0) if quick else (20.0, 10.0)
    nominal = load_panda()
    arm_a, _hidden_truth = concealed_panda(nominal, seed=0)  # the truth is not used below
    arm_b = kitchen_panda(nominal.joint_names)
    limits = model_limits(nominal).within(*arm_a.q_limits).within(*arm_b.q_limits)

    say("arm: excitation design")
    t0 = time.perf_counter()
    exc = design_excitation(nominal, limits, base_frequency=0.1, harmonics=5,
                            samples=60 if quick else 100, max_iterations=5 if quick else 40)
    t_design = time.perf_counter() - t0
    plan = excitation_plan(nominal, exc.trajectory, duration)
    test_traj = random_fourier(nominal.nq, limits, base_frequency=0.15, harmonics=5, seed=7)
    test_plan = excitation_plan(nominal, test_traj, test_duration)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_recording(out_dir / "excitation_plan.csv", plan)
        write_recording(out_dir / "test_plan.csv", test_plan)
    q_d, v_d, a_d = test_traj.evaluate(test_plan.t)
    t_split = plan.t[-1] * (1.0 - HELD_OUT_FRACTION)
    joints = nominal.joint_names

    arms, traces = {}, {}
    for arm in (arm_a, arm_b):
        say(f"arm: record {arm.name}")
        rec = record_plan(arm, plan, KP, KD, SensorNoise(), seed=1)
        rec_test = record_plan(arm, test_plan, KP, KD, SensorNoise(), seed=2)
        if out_dir is not None:
            write_recording(out_dir / f"{arm.name}_recording.csv", rec)
            write_recording(out_dir / f"{arm.name}_test_recording.csv", rec_test)
        fit_rec = rec.window(rec.t[0], t_split)

        say(f"arm: fit {arm.name}")
        t0 = time.perf_counter()
        idim = fit_idim_ls(nominal, fit_rec)
        t_idim = time.perf_counter() - t0
        t0 = time.perf_counter()
        cal = calibrate(nominal, fit_rec, method="inverse_dynamics", max_iter=1000)
        t_cal = time.perf_counter() - t0
        models = {"nominal": inverse_dynamics(nominal), "IDIM-LS": idim.inverse_dynamics(),
                  "kinemaforge_opt": embed(cal).inverse_dynamics}
        consistent = all(cal.model.link(n[: -len(".inertia")]).inertial.is_physically_consistent()
                         for n in cal.estimates if n.endswith(".inertia"))
        friction = {
            label: {"IDIM-LS": [float(x) for x in idim_x],
                    "kinemaforge_opt": [float(cal.estimates[f"{j}.{field}"].value[0]) for j in joints]}
            for label, idim_x, field in (("viscous", idim.viscous, "damping"), ("coulomb", idim.coulomb, "coulomb"))
        }
        held = dict(zip(HELD_OUT, (rec.window(t_split, rec.t[-1]), rec_test)))
        heldout = {h: {m: _rms_entry(held_out_rms(batched(fn), held[h])) for m, fn in models.items()} for h in HELD_OUT}

        say(f"arm: computed-torque tracking {arm.name}")
        tracking, traces[arm.name] = {}, {}
        for m, fn in models.items():
            res = track(arm, test_plan.t, q_d, v_d, a_d, fn, CT_KP, CT_KD, SensorNoise(), seed=3)
            tracking[m] = _rms_entry(1e3 * res.rms)
            traces[arm.name][m] = (res.t, 1e3 * np.linalg.norm(res.error, axis=1))
        arms[arm.name] = {
            "fit_duration_s": float(fit_rec.t[-1]), "rate_hz": float(1.0 / fit_rec.dt),
            "fit_time_s": {"nominal": None, "IDIM-LS": t_idim, "kinemaforge_opt": t_cal},
            "idim_base_parameters": int(idim.base.size),
            "ipopt_status": cal.status, "ipopt_iterations": int(cal.iterations),
            "identifiability": cal.identifiability[0], "physically_consistent": bool(consistent),
            "friction": friction, "heldout_torque_rms_nm": heldout, "tracking_rms_mrad": tracking,
        }

    result = {
        "quick": quick, "joints": list(joints), "models": list(MODELS),
        "excitation": {"duration_s": duration, "test_duration_s": test_duration,
                       "initial_condition": float(exc.initial_condition), "condition": float(exc.condition),
                       "iterations": int(exc.iterations), "design_time_s": t_design},
        "arms": arms, "total_s": time.perf_counter() - t_start,
    }
    if out_dir is not None:
        plot_side_by_side(result, traces, out_dir)
    return result


def plot_side_by_side(result: dict, traces: dict, out_dir: Path) -> tuple[Path, Path]:
    """Write ``tracking_error.png`` (|q - q_des| over time [mrad] and tracking RMS per joint) and
    ``heldout_torque.png`` (held-out torque RMS per joint [N·m]) into ``out_dir``, one row per
    arm.  traces: arm -> model -> (t (T,) [s], |q - q_des| (T,) [mrad])."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(result["joints"])
    ticks = (np.arange(n) + 0.27, [str(i + 1) for i in range(n)])
    fig, axes = plt.subplots(2, 2, figsize=(12, 7))
    tfig, tax = plt.subplots(2, 2, figsize=(12, 7))
    for row, (name, arm) in enumerate(result["arms"].items()):
        for col, h in enumerate(HELD_OUT):
            for k, m in enumerate(MODELS):
                tax[row, col].bar(np.arange(n) + 0.27 * k, arm["heldout_torque_rms_nm"][h][m]["per_joint"], width=0.27, label=m)
            tax[row, col].set(title=f"{name}: held-out torque RMS, {h}", xlabel="joint", ylabel="[N·m]", yscale="log")
            tax[row, col].set_xticks(*ticks)
            tax[row, col].legend()
        for k, m in enumerate(MODELS):
            axes[row, 0].semilogy(*traces[name][m], label=m)
            axes[row, 1].bar(np.arange(n) + 0.27 * k, arm["tracking_rms_mrad"][m]["per_joint"], width=0.27, label=m)
        axes[row, 0].set(title=f"{name}: |q - q_des|", xlabel="t [s]", ylabel="[mrad]")
        axes[row, 1].set(title=f"{name}: RMS per joint", xlabel="joint", ylabel="[mrad]", yscale="log")
        axes[row, 1].set_xticks(*ticks)
        for ax in axes[row]:
            ax.legend()
    paths = (Path(out_dir) / "tracking_error.png", Path(out_dir) / "heldout_torque.png")
    for f, p in zip((fig, tfig), paths):
        f.tight_layout()
        f.savefig(p, dpi=100)
        plt.close(f)
    return paths
