"""Batch jobs: ``job(input_dir, out_dir) -> dict`` (a JSON-able summary).  A job raises on bad
input; the runner records the error and carries on."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputFileError


def _pair(input_dir: Path) -> tuple[Path, Path]:
    urdf, rec = input_dir / "model.urdf", input_dir / "recording.csv"
    for p in (urdf, rec):
        if not p.is_file():
            raise InputFileError(f"batch input {str(input_dir)!r} has no {p.name}")
    return urdf, rec


def diagnose_job(input_dir: str | Path, out_dir: str | Path) -> dict:
    """``kinemaforge diagnose`` on INPUT/model.urdf + INPUT/recording.csv into ``out_dir``
    (without the Drake drift comparison); returns the effects and held-out RMS."""
    from ..io.recording import read_recording
    from ..model import read_urdf
    from ..physics.diagnose import diagnose
    from ..physics.report import write_diagnosis

    urdf, rec_path = _pair(Path(input_dir))
    rec = read_recording(rec_path)
    d = diagnose(read_urdf(urdf), rec)
    write_diagnosis(d, rec, out_dir, with_drift=False)
    return {"effects": [f"{e.joint}:{e.type}={e.value:.4g} {e.unit}" for e in d.effects],
            "rms_before": d.held_out.rms_before if d.held_out else None,
            "rms_after": d.held_out.rms_after if d.held_out else None}


def calibrate_job(input_dir: str | Path, out_dir: str | Path) -> dict:
    """``kinemaforge calibrate`` (damping and Coulomb friction of every joint) on
    INPUT/model.urdf + INPUT/recording.csv; writes OUT/model.urdf and OUT/calibration.json."""
    import json

    from ..calibration import calibrate
    from ..io.atomic import write_text_atomic
    from ..io.recording import read_recording
    from ..model import read_urdf, write_urdf

    urdf, rec_path = _pair(Path(input_dir))
    cal = calibrate(read_urdf(urdf), read_recording(rec_path))
    out = Path(out_dir)
    write_urdf(cal.model, out / "model.urdf")
    write_text_atomic(out / "calibration.json", json.dumps(cal.to_dict(), indent=2))
    return {"converged": cal.success, "estimates": {k: e.value.tolist() for k, e in cal.estimates.items()}}


def reconstruct_job(input_dir: str | Path, out_dir: str | Path) -> dict:
    """``kinemaforge reconstruct`` on an RGB-D sequence folder (``sequence.json`` inside) into
    ``out_dir``, then the Drake verification of the reconstruction; returns the joints and the
    drift per horizon [m]."""
    from ..perception.reconstruct import reconstruct_sequence
    from ..verify.reconstruction import verify_reconstruction

    seq = Path(input_dir)
    if not (seq / "sequence.json").is_file():
        raise InputFileError(f"batch input {str(seq)!r} is not an RGB-D sequence (no sequence.json)")
    rec = reconstruct_sequence(seq, out_dir, show_progress=False)
    joints = [f"{j['name']}:{j['type']} {j['parent']}->{j['child']}" for j in rec.document["joints"]]
    if not rec.model.movable_joints:
        return {"joints": joints, "drift_m": None}
    v = verify_reconstruction(out_dir, seq, reconstruction=rec)
    return {"joints": joints, "drift_m": v["drift_m"], "energy_residual": v["energy_residual"]}


JOBS = {"diagnose": diagnose_job, "calibrate": calibrate_job, "reconstruct": reconstruct_job}
