"""``kinemaforge --help`` answers without loading the pipeline's heavy libraries."""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("casadi", "open3d", "pydrake", "yourdfpy", "trimesh", "mujoco", "kinemaforge_opt.calibration")


def test_the_parser_loads_no_heavy_library():
    """Building every command's parser (what `kinemaforge --help` and an argument error do) must
    not import CasADi, open3d, Drake, yourdfpy, trimesh or MuJoCo: each costs seconds."""
    code = ("import sys; from kinemaforge_opt.cli import build_parser; build_parser(); "
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out


def test_the_density_help_names_the_default_in_use(capsys):
    from kinemaforge_opt.cli import main
    from kinemaforge_opt.perception.reconstruct import DEFAULT_DENSITY

    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    assert f"DEFAULT_DENSITY, {DEFAULT_DENSITY:g}" in " ".join(capsys.readouterr().out.split())


def test_lazy_public_names_resolve():
    import kinemaforge_opt
    from kinemaforge_opt import ArticulatedModel, calibrate, read_urdf

    assert callable(calibrate) and callable(read_urdf) and isinstance(ArticulatedModel, type)
    try:
        kinemaforge_opt.no_such_name
    except AttributeError as e:
        assert "no_such_name" in str(e)
    else:
        raise AssertionError("an unknown attribute must raise AttributeError")


def test_version(capsys):
    import kinemaforge_opt
    from kinemaforge_opt.cli import main

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"kinemaforge {kinemaforge_opt.__version__}"
