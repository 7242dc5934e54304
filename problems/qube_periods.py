"""The Qube's pendulum period against amplitude, next to the nominal model's two limits.

    PYTHONPATH=. .venv/bin/python -m problems.qube_periods [CSV ...]

For each recording (default: fin1, fin2, fin3, fin5 of ../shared/data/real/qube) prints the time
between successive pendulum peaks against the peak's amplitude, and the small-oscillation periods of
models/furuta/furuta.urdf linearised about hanging: the coupled mode (arm free to turn, as the model
has it) and the fixed-pivot mode (arm held still, i.e. stuck by friction).  Linearisation: solve
K x = w^2 M x with M = CRBA(q0) and K = d(gravity torque)/dq (central differences) from Pinocchio.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.signal import find_peaks

from kinemaforge_opt.io.qube import read_qube_csv
from kinemaforge_opt.model import read_urdf
from kinemaforge_opt.model.pinocchio import build_pin_model

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "qube" / "QQS2_data_diffx0"
URDF = Path(__file__).resolve().parents[1] / "models" / "furuta" / "furuta.urdf"


def model_periods(urdf: Path = URDF) -> tuple[float, float]:
    """(coupled, fixed-pivot) small-oscillation periods [s] of the pendulum about hanging."""
    pm = build_pin_model(read_urdf(urdf))
    data = pm.createData()
    q0 = pin.neutral(pm)
    M = pin.crba(pm, data, q0)
    M = np.triu(M) + np.triu(M, 1).T
    K = np.zeros((pm.nv, pm.nv))
    h = 1e-6
    for i in range(pm.nv):
        dq = np.zeros(pm.nv)
        dq[i] = h
        K[:, i] = (pin.computeGeneralizedGravity(pm, data, pin.integrate(pm, q0, dq))
                   - pin.computeGeneralizedGravity(pm, data, pin.integrate(pm, q0, -dq))) / (2 * h)
    w2 = np.linalg.eigvals(np.linalg.solve(M, K)).real
    coupled = 2 * np.pi / np.sqrt(w2.max())
    fixed = 2 * np.pi / np.sqrt(K[1, 1] / M[1, 1])  # arm held: the pendulum row alone
    return float(coupled), float(fixed)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv", nargs="*", type=Path,
                    default=[DATA / f"example_csv_fin{k}.csv" for k in (1, 2, 3, 5)])
    args = ap.parse_args()
    coupled, fixed = model_periods()
    print(f"nominal model: coupled-mode period {coupled:.3f} s (arm free), fixed-pivot {fixed:.3f} s (arm held)")
    print(f"{'recording':24s} {'amplitude [rad]':>16s} {'period [s]':>11s} {'arm speed [rad/s]':>18s}")
    for path in args.csv:
        rec = read_qube_csv(path)
        alpha, theta = rec.q[:, 1], rec.q[:, 0]
        peaks, _ = find_peaks(alpha, distance=40)
        arm_speed = np.abs(np.gradient(theta, rec.t))
        for a, b in zip(peaks[:-1], peaks[1:]):
            print(f"{path.stem:24s} {alpha[a]:16.3f} {rec.t[b] - rec.t[a]:11.3f} {arm_speed[a:b].mean():18.3f}")


if __name__ == "__main__":
    main()
