"""Calibration inside model-based control: excite a Panda, identify its dynamics, track better.

Nominal model: the Panda URDF of example-robot-data.  "Real" robots (MuJoCo, never seen by the
estimators): (a) that URDF with concealed inertia/armature/damping/friction changes, (b) the
independently authored Franka Kitchen Panda of gymnasium-robotics.

Steps: design a Fourier excitation (cond of the regressor) -> drive each real arm along it with
PD + feedforward, recording q, v and the applied torque at 1 kHz with sensor noise -> identify
(IDIM-LS and kinemaforge_opt.calibrate(method="inverse_dynamics"), embedded with
arm.embedding.embed) -> held-out torque prediction on the last
quarter of the excitation and on a second trajectory -> computed-torque tracking of the second
trajectory with each model.  Prints tables, writes recordings and two PNGs.  Headless.

    PYTHONPATH=. .venv/bin/python examples/08_arm_calibration.py [-o OUT] [--quick]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from kinemaforge_opt.calibration import calibrate  # noqa: E402
from kinemaforge_opt.arm.control import inverse_dynamics, track  # noqa: E402
from kinemaforge_opt.arm.embedding import embed  # noqa: E402
from kinemaforge_opt.arm.excitation import (  # noqa: E402
    design_excitation,
    excitation_plan,
    model_limits,
    random_fourier,
)
from kinemaforge_opt.arm.idim import batched, fit_idim_ls, held_out_rms  # noqa: E402
from kinemaforge_opt.arm.mujoco_real import SensorNoise, concealed_panda, kitchen_panda, record_plan  # noqa: E402
from kinemaforge_opt.arm.panda import load_panda  # noqa: E402
from kinemaforge_opt.io.recording import write_recording  # noqa: E402

KP = np.array([600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0])  # recording PD gains [N·m/rad]
KD = np.array([50.0, 50.0, 50.0, 20.0, 20.0, 20.0, 10.0])  # [N·m·s/rad]
CT_KP, CT_KD = 100.0, 20.0  # computed-torque outer loop [1/s², 1/s]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("out/08_arm_calibration"))
    ap.add_argument("--quick", action="store_true", help="short excitation design and recordings")
    args = ap.parse_args()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    duration, test_duration = (6.0, 5.0) if args.quick else (20.0, 10.0)

    nominal = load_panda()
    arm_a, _hidden_truth = concealed_panda(nominal, seed=0)  # the truth is not used below
    arm_b = kitchen_panda(nominal.joint_names)
    limits = model_limits(nominal).within(*arm_a.q_limits).within(*arm_b.q_limits)

    t0 = time.perf_counter()
    exc = design_excitation(nominal, limits, base_frequency=0.1, harmonics=5,
                            samples=60 if args.quick else 100, max_iterations=5 if args.quick else 40)
    t_design = time.perf_counter() - t0
    print(f"excitation: cond(W_base) {exc.initial_condition:.1f} (random start) -> {exc.condition:.1f} "
          f"({exc.iterations} SLSQP iterations, {t_design:.1f} s)")
    plan = excitation_plan(nominal, exc.trajectory, duration)
    test_traj = random_fourier(nominal.nq, limits, base_frequency=0.15, harmonics=5, seed=7)
    test_plan = excitation_plan(nominal, test_traj, test_duration)
    write_recording(out / "excitation_plan.csv", plan)
    write_recording(out / "test_plan.csv", test_plan)
    q_d, v_d, a_d = test_traj.evaluate(test_plan.t)
    t_split = plan.t[-1] * 0.75

    fig, axes = plt.subplots(2, 2, figsize=(12, 7))
    tfig, tax = plt.subplots(2, 2, figsize=(12, 7))
    for row, arm in enumerate((arm_a, arm_b)):
        rec = record_plan(arm, plan, KP, KD, SensorNoise(), seed=1)
        rec_test = record_plan(arm, test_plan, KP, KD, SensorNoise(), seed=2)
        write_recording(out / f"{arm.name}_recording.csv", rec)
        write_recording(out / f"{arm.name}_test_recording.csv", rec_test)
        fit_rec = rec.window(rec.t[0], t_split)

        t0 = time.perf_counter()
        idim = fit_idim_ls(nominal, fit_rec)
        t_idim = time.perf_counter() - t0
        models = {"nominal": inverse_dynamics(nominal), "IDIM-LS": idim.inverse_dynamics()}
        t0 = time.perf_counter()
        cal = calibrate(nominal, fit_rec, method="inverse_dynamics", max_iter=1000)
        t_cal = time.perf_counter() - t0
        models["kinemaforge_opt"] = embed(cal).inverse_dynamics

        print(f"\n== real arm {arm.name}: fit on {fit_rec.t[-1]:.1f} s at {1 / fit_rec.dt:.0f} Hz")
        print(f"   IDIM-LS {t_idim:.2f} s, {idim.base.size} base parameters; kinemaforge_opt {t_cal:.2f} s, "
              f"{cal.status}, {cal.iterations} IPOPT iterations; {cal.identifiability[0]}")
        consistent = all(cal.model.link(n[: -len(".inertia")]).inertial.is_physically_consistent()
                         for n in cal.estimates if n.endswith(".inertia"))
        print(f"   identified inertias physically consistent: {consistent}")
        joints = nominal.joint_names
        for label, idim_x, field in (("viscous [N·m·s/rad]", idim.viscous, "damping"), ("Coulomb [N·m]", idim.coulomb, "coulomb")):
            ours = np.array([cal.estimates[f"{j}.{field}"].value[0] for j in joints])
            print(f"   {label:<20} IDIM-LS {np.round(idim_x, 3)}\n   {'':<20} kf_opt  {np.round(ours, 3)}")
        held = {"excitation last 25%": rec.window(t_split, rec.t[-1]), "second trajectory": rec_test}
        header = "   held-out torque RMS [N·m]           " + " ".join(f"{j[-6:]:>7}" for j in nominal.joint_names) + "    mean"
        print(header)
        for col, (hname, h) in enumerate(held.items()):
            for k, (mname, id_fn) in enumerate(models.items()):
                r = held_out_rms(batched(id_fn), h)
                print(f"   {hname:<19} {mname:<15} " + " ".join(f"{x:7.3f}" for x in r) + f" {r.mean():7.3f}")
                tax[row, col].bar(np.arange(nominal.nq) + 0.27 * k, r, width=0.27, label=mname)
            tax[row, col].set(title=f"{arm.name}: held-out torque RMS, {hname}", xlabel="joint", ylabel="[N·m]", yscale="log")
            tax[row, col].set_xticks(np.arange(nominal.nq) + 0.27, [str(i + 1) for i in range(nominal.nq)])
            tax[row, col].legend()
        print("   computed-torque tracking RMS [mrad] on the second trajectory")
        for mname, id_fn in models.items():
            res = track(arm, test_plan.t, q_d, v_d, a_d, id_fn, CT_KP, CT_KD, SensorNoise(), seed=3)
            r = 1e3 * res.rms
            print(f"   {mname:<35} " + " ".join(f"{x:7.2f}" for x in r) + f" {r.mean():7.2f}")
            axes[row, 0].semilogy(res.t, 1e3 * np.linalg.norm(res.error, axis=1), label=mname)
            axes[row, 1].bar(np.arange(nominal.nq) + 0.27 * list(models).index(mname), r, width=0.27, label=mname)
        axes[row, 0].set(title=f"{arm.name}: |q - q_des|", xlabel="t [s]", ylabel="[mrad]")
        axes[row, 1].set(title=f"{arm.name}: RMS per joint", xlabel="joint", ylabel="[mrad]", yscale="log")
        axes[row, 1].set_xticks(np.arange(nominal.nq) + 0.27, [str(i + 1) for i in range(nominal.nq)])
        for ax in axes[row]:
            ax.legend()
    fig.tight_layout()
    fig.savefig(out / "tracking_error.png", dpi=100)
    tfig.tight_layout()
    tfig.savefig(out / "heldout_torque.png", dpi=100)
    print(f"\nwrote {out / 'tracking_error.png'}, {out / 'heldout_torque.png'} and recordings in {out}")


if __name__ == "__main__":
    main()
