"""The examples in examples/ run as documented (in a fresh interpreter, as a user runs them)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(name: str, *args: str) -> str:
    done = subprocess.run([sys.executable, str(ROOT / "examples" / name), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_bridge_dynamics_example():
    out = _run("01_bridge_dynamics.py")
    assert "ABA: a =" in out and "d a / d [m, m·c_x]" in out


def test_diagnose_door_example_names_the_hidden_physics(tmp_path):
    """The example hides Coulomb friction 0.3 N·m and damping 0.2 N·m·s/rad in a MuJoCo door;
    diagnose must name both (and nothing else) within a quarter of the hidden values."""
    _run("02_diagnose_door.py", "-o", str(tmp_path))
    doc = json.loads((tmp_path / "diagnosis.json").read_text())
    found = {e["type"]: e["value"] for e in doc["effects"]}
    assert set(found) == {"coulomb_friction", "viscous_damping"}, found
    assert abs(found["coulomb_friction"] - 0.3) <= 0.25 * 0.3
    assert abs(found["viscous_damping"] - 0.2) <= 0.25 * 0.2
    assert (tmp_path / "model.urdf").is_file() and (tmp_path / "fit_before_after.png").is_file()
