"""Calibration inside model-based control: excite a Panda, identify its dynamics, track better.

Nominal model: the Panda URDF of example-robot-data.  "Real" robots (MuJoCo, never seen by the
estimators): (a) that URDF with concealed inertia/armature/damping/friction changes, (b) the
independently authored Franka Kitchen Panda of gymnasium-robotics.

Steps (:func:`kinemaforge_opt.arm.side_by_side.compare_arm_models`): design a Fourier excitation
(cond of the regressor) -> drive each real arm along it with PD + feedforward, recording q, v and
the applied torque at 1 kHz with sensor noise -> identify (IDIM-LS and
kinemaforge_opt.calibrate(method="inverse_dynamics"), embedded with arm.embedding.embed) ->
held-out torque prediction on the last quarter of the excitation and on a second trajectory ->
computed-torque tracking of the second trajectory with each model.  Prints tables, writes
recordings and two PNGs.  Headless.

    PYTHONPATH=. .venv/bin/python examples/04_arm_calibration.py [-o OUT] [--quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from kinemaforge_opt.arm.side_by_side import HELD_OUT, MODELS, compare_arm_models


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("out/04_arm_calibration"))
    ap.add_argument("--quick", action="store_true", help="short excitation design and recordings")
    args = ap.parse_args()
    res = compare_arm_models(args.quick, args.out)
    exc = res["excitation"]
    print(f"excitation: cond(W_base) {exc['initial_condition']:.1f} (random start) -> {exc['condition']:.1f} "
          f"({exc['iterations']} SLSQP iterations, {exc['design_time_s']:.1f} s)")
    for name, arm in res["arms"].items():
        t = arm["fit_time_s"]
        print(f"\n== real arm {name}: fit on {arm['fit_duration_s']:.1f} s at {arm['rate_hz']:.0f} Hz")
        print(f"   IDIM-LS {t['IDIM-LS']:.2f} s, {arm['idim_base_parameters']} base parameters; kinemaforge_opt "
              f"{t['kinemaforge_opt']:.2f} s, {arm['ipopt_status']}, {arm['ipopt_iterations']} IPOPT iterations; "
              f"{arm['identifiability']}")
        print(f"   identified inertias physically consistent: {arm['physically_consistent']}")
        for label, key in (("viscous [N·m·s/rad]", "viscous"), ("Coulomb [N·m]", "coulomb")):
            f = arm["friction"][key]
            print(f"   {label:<20} IDIM-LS {np.round(f['IDIM-LS'], 3)}\n"
                  f"   {'':<20} kf_opt  {np.round(f['kinemaforge_opt'], 3)}")
        print("   held-out torque RMS [N·m]           " + " ".join(f"{j[-6:]:>7}" for j in res["joints"]) + "    mean")
        for h in HELD_OUT:
            for m in MODELS:
                r = arm["heldout_torque_rms_nm"][h][m]
                print(f"   {h:<19} {m:<15} " + " ".join(f"{x:7.3f}" for x in r["per_joint"]) + f" {r['mean']:7.3f}")
        print("   computed-torque tracking RMS [mrad] on the second trajectory")
        for m in MODELS:
            r = arm["tracking_rms_mrad"][m]
            print(f"   {m:<35} " + " ".join(f"{x:7.2f}" for x in r["per_joint"]) + f" {r['mean']:7.2f}")
    print(f"\nwrote {args.out / 'tracking_error.png'}, {args.out / 'heldout_torque.png'} and recordings in {args.out} "
          f"({res['total_s']:.0f} s)")


if __name__ == "__main__":
    main()
