"""02 — Find the physics a door model leaves out.

A cabinet door with hidden Coulomb friction and viscous damping is simulated in MuJoCo (the
independent ground truth), sampled at 30 Hz with 2 mrad noise; ``diagnose`` locates the mismatch,
names the effects with 95 % intervals, re-fits, and compares held-out predictions.  Writes
diagnosis.json, the augmented URDF and the plots to OUT (default out/02_diagnose_door).

    .venv/bin/python examples/02_diagnose_door.py [-o OUT]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from kinemaforge_opt.io.recording import Recording
from kinemaforge_opt.physics.diagnose import diagnose
from kinemaforge_opt.physics.report import write_diagnosis
from kinemaforge_opt.synth.effects import ConcealedEffect
from kinemaforge_opt.synth.groundtruth import HandPlan, simulate
from kinemaforge_opt.synth.objects import make_object


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("out/02_diagnose_door"))
    args = ap.parse_args()

    obj = make_object("cabinet", 0)
    joint = obj.model.joint_names[0]
    hidden = (ConcealedEffect("coulomb_friction", joint, 0.3), ConcealedEffect("viscous_damping", joint, 0.2))
    ep = simulate(obj.model, obj.handles, hidden, plan=HandPlan(goals=(0.5, 0.3), push_s=0.8, free_s=1.7, release_speed=0.15), record_hz=30)
    rng = np.random.default_rng(0)
    rec = Recording(ep.t, ep.joint_names, ep.q + rng.normal(0.0, 2e-3, ep.q.shape), tau=ep.tau)

    d = diagnose(obj.model, rec, progress=lambda s: print(f"  … {s}"))
    print(d.summary())
    print("hidden: " + ", ".join(f"{e.type} = {e.value}" for e in hidden))
    paths = write_diagnosis(d, rec, args.out)
    print("wrote " + ", ".join(str(p) for p in paths.values()))


if __name__ == "__main__":
    main()
