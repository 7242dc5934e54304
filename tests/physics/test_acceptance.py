"""The prediction check that model-form error forces on ``diagnose``: which span can judge effects
(``prediction_signal``), and the plain-words summary of what each check dropped."""

from __future__ import annotations

import numpy as np
import pytest

from kinemaforge_opt.physics.diagnose import Diagnosis, FoundEffect
from kinemaforge_opt.physics.predict import HeldOut, prediction_signal


def _held(err_per_joint, T=200):
    """A span whose nominal prediction errs by a sinusoid of RMS ``err_per_joint`` [rad] per joint."""
    t = np.linspace(0.0, 2.0, T)
    q = np.zeros((T, len(err_per_joint)))
    wave = np.sqrt(2.0) * np.sin(2 * np.pi * 5 * t)[:, None]  # RMS 1 over whole periods
    return HeldOut(t, q, q + wave * np.asarray(err_per_joint), q)


def test_prediction_signal_is_the_worst_joint_error_in_noise_sigmas():
    sigma = np.array([0.002, 0.001])
    # joint 0 errs by 0.004 rad = 2 sigma, joint 1 by 0.005 rad = 5 sigma: the span shows 5 sigma
    assert prediction_signal(_held([0.004, 0.005]), sigma) == pytest.approx(5.0, rel=1e-2)
    # a system at rest that the nominal model predicts to the noise cannot judge an effect
    assert prediction_signal(_held([0.001, 0.0005]), sigma) < 3.0
    assert prediction_signal(HeldOut(np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2))), sigma) == 0.0


def _diagnosis(effects=(), dropped=None, acceptance=None, held_out_used=False, others=(), tested=()):
    return Diagnosis((), tuple(effects), tuple(tested), None, None, None, None, tuple(others),
                     held_out_used_for_selection=held_out_used, acceptance_check=acceptance, dropped=dropped or {})


def test_summary_blames_the_interval_check_when_it_dropped_every_effect():
    reason = "its 95% interval [-0.01, 0.03] N*m*s/rad holds its off value 0"
    d = _diagnosis(dropped={"interval_check": ["viscous_damping on j0"]}, held_out_used=True,
                   acceptance={"span": "held_out", "reason": "held-out span judged", "signal_sigma": {}},
                   tested=[{"interval_check": "viscous_damping on j0", "dropped": True, "reason": reason}])
    text = d.summary()
    assert "viscous damping on j0" in text and f"the full-rate re-fit does not support it ({reason})" in text
    assert "predicts the held-out span better" not in text


def test_summary_blames_the_acceptance_check_and_names_its_span():
    h = _held([0.01, 0.01])
    d = _diagnosis(dropped={"acceptance_check": ["spring on j0"]}, others=(h, h),
                   acceptance={"span": "other_recording_2", "reason": "judged on other recording 2", "signal_sigma": {}})
    text = d.summary()
    assert "predicts the other recording 2 better (dropped: spring on j0)" in text
    assert d.other_used_for_selection == 1
    lines = [ln for ln in text.splitlines() if ln.startswith("other recording")]
    assert "not independent" in lines[1] and "not independent" not in lines[0]


def test_summary_lists_effects_a_check_dropped_beside_those_kept():
    kept = FoundEffect("j0", "viscous_damping", 0.2, "N*m*s/rad", (0.18, 0.22), -50.0, {})
    d = _diagnosis(effects=[kept], dropped={"interval_check": ["axis_tilt on j0"]},
                   acceptance={"span": None, "reason": "no span outside the fit can show an effect", "signal_sigma": {}})
    text = d.summary()
    assert "missing physics on j0: viscous damping" in text
    assert "dropped axis tilt on j0: its 95% interval holding the off value" in text
    assert "(no span outside the fit can show an effect)" in text
    assert d.other_used_for_selection is None


def test_cli_rejects_a_max_effects_below_one(tmp_path, capsys):
    from pathlib import Path

    from kinemaforge_opt.cli import main as cli_main
    from kinemaforge_opt.io.recording import Recording, write_recording

    t = np.linspace(0.0, 2.0, 61)
    csv = tmp_path / "rec.csv"
    write_recording(csv, Recording(t, ("theta", "alpha"), np.stack([0.1 * np.sin(t), 0.2 * np.cos(5 * t)], axis=1)))
    urdf = Path(__file__).resolve().parents[2] / "models" / "furuta" / "furuta.urdf"
    code = cli_main(["diagnose", str(urdf), str(csv), "-o", str(tmp_path / "out"), "--max-effects", "0"])
    assert code == 2
    assert "--max-effects must be at least 1, got 0" in capsys.readouterr().err


def test_summary_says_a_held_out_span_without_signal_says_nothing():
    h = _held([0.001, 0.001])
    d = Diagnosis((), (), (), None, None, None, h, (), acceptance_check={
        "span": "other_recording_1", "reason": "judged on other recording 1",
        "signal_sigma": {"held_out": 1.7, "other_recording_1": 41.0}})
    assert "errs there by only 1.7 noise sigmas" in d.summary()


def test_quantisation_sigma_is_the_encoder_step_over_root_twelve():
    from kinemaforge_opt.nlp.joint_space import quantisation_sigma

    step = 2 * np.pi / 2048
    t = np.linspace(0, 3, 300)
    q = np.stack([np.round(0.3 * np.sin(t) / step) * step, 0.3 * np.sin(t)], axis=1)
    q[:100, 0] = q[100, 0]  # standing still for a while: no change, not a step
    s = quantisation_sigma(q)
    assert s[0] == pytest.approx(step / np.sqrt(12), rel=1e-6)
    assert s[1] < 1e-3 * step  # an unquantised signal has no rounding floor


def test_diagnose_help_names_every_candidate_effect_and_the_threshold():
    """`kinemaforge diagnose --help` lists the effect library the search tests and its ΔBIC
    threshold (the help text is written out, so that the command starts without importing the
    solvers; this keeps it true)."""
    from kinemaforge_opt.commands.diagnose import EPILOG
    from kinemaforge_opt.physics.selection import CANDIDATES, DELTA_BIC

    library = EPILOG.split("tests the effect library (", 1)[1].split(")", 1)[0]
    assert [name.strip() for name in library.replace("\n", " ").split(",")] == list(CANDIDATES)
    assert f"ΔBIC < {DELTA_BIC:g}" in EPILOG


def test_a_quantised_encoder_mostly_at_rest_is_not_called_noiseless():
    """A real pendulum comes to rest: most third differences of its quantised angle are exactly 0,
    so their MAD reads no noise at all and every misfit counted as millions of sigmas (the Qube's
    fin3 arm); its measurement error is at least the encoder's rounding error."""
    from kinemaforge_opt.nlp.joint_space import measurement_sigma, noise_std

    step = 2 * np.pi / 2048
    t = np.linspace(0, 10, 1000)
    q = np.round(0.4 * np.exp(-t) * np.sin(6 * t) / step)[:, None] * step
    assert noise_std(q)[0] < 1e-8
    assert measurement_sigma(q)[0] == pytest.approx(step / np.sqrt(12), rel=1e-6)


class _Checks:
    """Stand-in for :class:`~kinemaforge_opt.physics.selection.EffectSearch`'s three checks, each
    dropping the effects a rule of its own refutes: what ``checks`` calls, and in what order."""

    def __init__(self, selected, refutes):
        self.selected, self.refutes, self.calls = list(selected), refutes, []

    def _check(self, name):
        self.calls.append((name, tuple(self.selected)))
        self.selected = [e for e in self.selected if not self.refutes[name](self.selected, e)]

    def simulation_check(self):
        self._check("simulation")

    def acceptance_check(self, held):
        self._check("acceptance")
        return {"span": None}, False

    def held_out_check(self, held):
        self._check("held_out")
        return held is not None


def test_what_a_later_check_leaves_is_judged_again_by_every_check():
    """The held-out check drops the damping; the stop left alone then fails the simulation check
    (a stop judged only beside the damping): the set reported is one every check passed."""
    from kinemaforge_opt.physics.selection import EffectSearch

    refutes = {"simulation": lambda s, e: e == "stop" and s == ["stop"],
               "acceptance": lambda s, e: False,
               "held_out": lambda s, e: e == "damping"}
    search = _Checks(["damping", "stop"], refutes)
    acceptance, judged = EffectSearch.checks(search, held="span")
    assert search.selected == [] and judged
    assert search.calls == [("simulation", ("damping", "stop")), ("acceptance", ("damping", "stop")),
                            ("held_out", ("damping", "stop")), ("simulation", ("stop",))]
    # a set every check passes first time is judged once by each
    search = _Checks(["damping"], {k: (lambda s, e: False) for k in refutes})
    EffectSearch.checks(search, held=None)
    assert [c for c, _ in search.calls] == ["simulation", "acceptance", "held_out"]
    # with nothing selected each check still runs once (the acceptance record says which span judged)
    search = _Checks([], {k: (lambda s, e: False) for k in refutes})
    assert EffectSearch.checks(search, held=None) == ({"span": None}, False)
    assert [c for c, _ in search.calls] == ["simulation", "acceptance", "held_out"]
