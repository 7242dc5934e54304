"""Write a diagnosis to disk: ``diagnosis.json`` (DESIGN.md contract), the augmented model,
and the plots."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic
from ..io.recording import Recording
from ..model import write_urdf
from .diagnose import Diagnosis
from .plots import plot_diagnosis


def drift_before_after(d: Diagnosis, recording: Recording) -> dict[str, dict[str, float]]:
    """Drake drift [m] of the nominal and the augmented model replaying ``recording``, at the
    horizons (1, 5, 10, 20, 50 s) that fall inside it."""
    from ..verify import drift

    duration = recording.t[-1] - recording.t[0]
    horizons = tuple(h for h in (1.0, 5.0, 10.0, 20.0, 50.0) if h <= duration) or (float(duration),)
    out = {}
    for label, model in (("before", d.nominal_fit.model), ("after", d.model)):
        rep = drift(model, recording.select(model.joint_names), horizons_s=horizons, discrete=False)
        out[label] = {f"{h:g}": float(x) for h, x in zip(rep.horizons_s, rep.drift_m)}
    return out


def diagnosis_dict(d: Diagnosis, drift_m: dict | None = None) -> dict:
    """The ``diagnosis.json`` document."""
    fit = {}
    scored = d.held_out is not None and d.held_out.scored  # else no held-out RMS (null)
    for label, rms in (("before", d.held_out.rms_before if scored else None),
                       ("after", d.held_out.rms_after if scored else None)):
        fit[label] = {"rms": rms, "drift_m": (drift_m or {}).get(label, {}),
                      "fit_rms": float(np.sqrt(np.mean(((d.nominal_fit if label == "before" else d.final_fit).q_fit
                                                         - d.nominal_fit.recording.q) ** 2)))}
    return {
        "mismatch": [{"joint": m.joint, "windows_s": [list(w) for w in m.windows_s],
                      "share_of_residual": m.share_of_residual, "rms_over_noise": m.rms_over_noise,
                      "regions": m.regions} for m in d.mismatch],
        "effects": [e.to_dict() for e in d.effects],
        "tested": list(d.tested),
        "fit": fit,
        "held_out_used_for_selection": d.held_out_used_for_selection,
        "acceptance_check": d.acceptance_check,
        "dropped": d.dropped,
        "others": [{"rms_before": h.rms_before if h.scored else None, "rms_after": h.rms_after if h.scored else None,
                    "used_for_selection": k == d.other_used_for_selection} for k, h in enumerate(d.held_out_others)],
    }


def write_diagnosis(d: Diagnosis, recording: Recording, out_dir: str | Path, with_drift: bool = True) -> dict[str, Path]:
    """Write diagnosis.json, model.urdf (augmented) and the PNG plots into ``out_dir``."""
    out_dir = Path(out_dir)
    drift_m = drift_before_after(d, recording) if with_drift else None
    paths = {"model": write_urdf(d.model, out_dir / "model.urdf")}
    paths["diagnosis"] = out_dir / "diagnosis.json"
    write_text_atomic(paths["diagnosis"], json.dumps(diagnosis_dict(d, drift_m), indent=2))
    for p in plot_diagnosis(d, out_dir):
        paths[p.stem] = p
    return paths
