"""The bench table writer on a tiny hand-made subset (structure only, not a measurement)."""

import json

from kinemaforge_opt.bench.discovery import CaseScore, as_dicts, summarise
from kinemaforge_opt.bench.report import NOT_MEASURED, write_report


def _arm():
    """A two-joint, one-arm stand-in for a ``compare_arm_models`` result."""
    models = ("nominal", "IDIM-LS", "kinemaforge_opt")
    rms = lambda x: {"per_joint": [x, 2 * x], "mean": 1.5 * x}  # noqa: E731
    return {
        "quick": True, "joints": ["panda_joint1", "panda_joint2"], "models": list(models),
        "excitation": {"duration_s": 6.0, "test_duration_s": 5.0, "initial_condition": 483.0, "condition": 83.3,
                       "iterations": 5, "design_time_s": 7.7},
        "arms": {"panda_kitchen": {
            "fit_duration_s": 4.5, "rate_hz": 1000.0, "fit_time_s": {"nominal": None, "IDIM-LS": 0.6, "kinemaforge_opt": 1.3},
            "idim_base_parameters": 20, "ipopt_status": "Solve_Succeeded", "ipopt_iterations": 160,
            "identifiability": "…", "physically_consistent": True,
            "friction": {k: {"IDIM-LS": [0.1, 0.2], "kinemaforge_opt": [0.1, 0.2]} for k in ("viscous", "coulomb")},
            "heldout_torque_rms_nm": {h: {m: rms(x) for m, x in zip(models, (1.0, 0.16, 0.15))}
                                      for h in ("excitation last 25%", "second trajectory")},
            "tracking_rms_mrad": {m: rms(x) for m, x in zip(models, (150.0, 3.0, 1.8))},
        }},
        "total_s": 18.0,
    }


def _result():
    scores = [
        CaseScore("effect_door_spring", "diagnose", ("spring",), ("spring",), 1, 0, 0, {"spring": 0.02}, 0.04, 0.004, 5.0,
                  other_rms_before=0.4, other_rms_after=0.004),
        CaseScore("effect_door_spring", "ID-LS", ("spring",), ("constant_bias",), 0, 1, 1, {}, 0.04, 0.05, 0.01,
                  other_rms_before=0.4, other_rms_after=0.5),
        CaseScore("null_door", "diagnose", (), (), 0, 0, 0, {}, 0.01, 0.01, 3.0),
        CaseScore("null_door", "ID-LS", (), ("viscous_damping",), 0, 1, 0, {}, 0.01, 0.02, 0.01),
    ]
    return {
        "size": "test", "machine": "test", "total_s": 1.0,
        "discovery": {"summary": summarise(scores), "cases": as_dicts(scores)},
        "sturm": {}, "calibration": [{"seed": 0, "converged": True, "axis_error_deg": 0.1, "damping": 0.21,
                                      "damping_rel_error": 0.05, "coulomb": 0.3, "coulomb_rel_error": 0.0,
                                      "samples": 76, "solve_time_s": 1.0}],
        "scaling": {"points": [{"rate_hz": 30, "samples": 76, "time_s": 1.0, "iterations": 5, "converged": True},
                               {"rate_hz": 60, "samples": 151, "time_s": 4.0, "iterations": 5, "converged": True}],
                    "exponent": 2.0},
        "arm": _arm(), "stage_time_s": {"diagnose per case (diagnose)": 4.0},
    }


def test_summary_scores():
    s = _result()["discovery"]["summary"]
    assert s["diagnose"]["f1"] == 1.0 and s["diagnose"]["null_false_positives"] == 0
    assert s["ID-LS"]["f1"] == 0.0 and s["ID-LS"]["null_false_positives"] == 1
    assert s["diagnose"]["median_heldout_gain"] == 10.0
    assert s["diagnose"]["median_other_gain"] == 100.0 and s["diagnose"]["other_gain_at_bar"] == 1.0
    assert s["ID-LS"]["median_other_gain"] == 0.8 and s["ID-LS"]["other_gain_at_bar"] == 0.0


def test_supported_cases_leave_out_only_effects_the_recording_does_not_show():
    # one effect the recording supports (found), one it does not (missed), one null case
    scores = [
        CaseScore("effect_door_spring", "diagnose", ("spring",), ("spring",), 1, 0, 0, {}, 0.04, 0.004, 1.0,
                  oracle_delta_bic=-600.0),
        CaseScore("effect_door_stribeck_friction", "diagnose", ("stribeck_friction",), (), 0, 0, 1, {}, 0.01, 0.01, 1.0,
                  oracle_delta_bic=7.0),
        CaseScore("null_door", "diagnose", (), (), 0, 0, 0, {}, 0.01, 0.01, 1.0),
    ]
    s = summarise(scores)["diagnose"]
    assert s["f1"] == 2 / 3 and s["supported_cases"] == 2 and s["f1_supported"] == 1.0
    assert [c["supported"] for c in as_dicts(scores)] == [True, False, True]


def test_write_report(tmp_path):
    paths = write_report(_result(), tmp_path)
    md = paths["markdown"].read_text()
    assert "Mismatch discovery" in md and "| diagnose | 2 |" in md
    assert md.count(NOT_MEASURED) >= 6 * 5 + 5 * 5  # Table 1 and Table 2 cells are placeholders
    assert "| panda_kitchen | kinemaforge_opt | 0.225 | 0.225 | 2.70 | 1.30 |" in md
    assert "| panda_kitchen | nominal | tracking RMS [mrad] | 150.00 | 300.00 |" in md
    assert json.loads(paths["json"].read_text())["size"] == "test"
    assert paths["scaling"].stat().st_size > 0 and paths["discovery"].stat().st_size > 0
