"""The rotation analysis of issue 45 (benchmarks/rotation_analysis.py): each candidate's fit
recovers the parameters a synthetic moment was built with, the wrong candidate predicts held-out
data worse, instruments undo errors-in-variables attenuation, and the band response reads a
gain and a delay as their closed forms."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from benchmarks import rotation_analysis as ra

N = 6000                       # 60 s at RATE_HZ


def _noise(seed: int, scale: float = 1e-4) -> np.ndarray:
    """Band-limited (0.2-25 Hz) random signal."""
    rng = np.random.default_rng(seed)
    sos = signal.butter(2, (0.2, 25.0), btype="bandpass", fs=ra.RATE_HZ, output="sos")
    x = signal.sosfiltfilt(sos, rng.standard_normal(N))
    return scale * x / x.std()


def _signals(torque, moment, flapping, rate=None, instrument=None) -> ra.RotationSignals:
    two = lambda x: None if x is None else np.column_stack([x, x])    # noqa: E731
    return ra.RotationSignals("synthetic", two(torque), two(moment), two(flapping),
                              two(np.zeros(N) if rate is None else rate), two(instrument),
                              np.zeros(N), None)


def test_scale_candidate_recovers_gain_delay_and_flapping():
    torque, flap = _noise(1), _noise(2, 1e3)
    moment = 0.7 * ra.delayed(torque, 0.005) + 3e-8 * flap
    fit = ra.fit_candidate([_signals(torque, moment, flap)], 0, "scale", blocks=4)
    assert fit.gain == pytest.approx(0.7, abs=0.01)
    assert fit.parameter == pytest.approx(0.005)
    assert fit.flapping == pytest.approx(3e-8, rel=0.02)
    assert fit.r2 > 0.99


def test_lag_candidate_recovers_time_constant_and_beats_scale_held_out():
    torque, flap = _noise(3), _noise(4, 1e3)
    moment = 0.9 * ra.lagged(torque, 0.02) + 3e-8 * flap
    sig = _signals(torque, moment, flap)
    torque2, flap2 = _noise(5), _noise(6, 1e3)
    held = _signals(torque2, 0.9 * ra.lagged(torque2, 0.02) + 3e-8 * flap2, flap2)
    lag = ra.fit_candidate([sig], 0, "lag", blocks=4)
    scale = ra.fit_candidate([sig], 0, "scale", blocks=4)
    assert lag.parameter == pytest.approx(0.02)
    assert lag.gain == pytest.approx(0.9, abs=0.02)
    assert ra.heldout_r2(lag, held, 0) > 0.99
    assert ra.heldout_r2(scale, held, 0) < ra.heldout_r2(lag, held, 0) - 0.01


def test_damping_candidate_recovers_k():
    torque, flap = _noise(7), _noise(8, 1e3)
    rate = _noise(9, 1.0)
    moment = 0.8 * torque - 2e-4 * rate + 3e-8 * flap
    fit = ra.fit_candidate([_signals(torque, moment, flap, rate)], 0, "damping", blocks=4)
    assert fit.gain == pytest.approx(0.8, abs=0.01)
    assert fit.parameter == pytest.approx(2e-4, rel=0.02)


def test_instruments_undo_errors_in_variables():
    """Noise of variance s^2 on the regressor of variance v attenuates least squares by
    v / (v + s^2) (here 1/2); the instrumented gain stays at the truth."""
    true, flap = _noise(10), _noise(11, 1e3)
    measured = true + _noise(12)                 # noise as large as the signal: gain 1/2
    instrument = true + _noise(13)
    sig = _signals(measured, true + 0.0 * flap, flap, instrument=instrument)
    ls = ra.fit_candidate([sig], 0, "scale", blocks=4)
    iv = ra.fit_candidate([sig], 0, "iv", blocks=4)
    assert ls.gain == pytest.approx(0.5, abs=0.05)
    assert iv.gain == pytest.approx(1.0, abs=0.05)


def test_band_transfer_reads_gain_and_delay():
    torque, flap = _noise(14), _noise(15, 1e3)
    delay = 0.01
    moment = 0.6 * ra.delayed(torque, delay) + 3e-8 * flap
    (h, coherence), = ra.band_transfer([torque, flap], moment, ((8.0, 12.0),))
    assert abs(h[0]) == pytest.approx(0.6, abs=0.02)
    # band centre 10 Hz: phase -360 f d = -36 deg (bins 8.2-11.7 Hz: -30..-42)
    assert np.degrees(np.angle(h[0])) == pytest.approx(-36.0, abs=4.0)
    assert abs(h[1]) == pytest.approx(3e-8, rel=0.05)
    assert coherence > 0.99


def test_low_band_balance_and_windowed_gain_read_a_built_balance():
    """tau - M = -c f below 2 Hz exactly: R^2 1 and c; M = 0.3 tau + 3e-8 f: the windowed
    least squares returns 0.3 and 3e-8."""
    torque, flap = _noise(16), _noise(17, 1e3)
    moment = torque + 4e-8 * flap
    balance = ra.low_band_balance(_signals(torque, moment, flap), 0)
    assert balance["flapping"] == pytest.approx(4e-8, rel=1e-3)
    assert balance["balance_r2"] == pytest.approx(1.0, abs=1e-3)
    thrust = 0.4 + _noise(22, 0.05)
    offset = ra.RotationSignals("synthetic", np.column_stack([torque, torque]),
                                np.column_stack([moment - 2e-3 * thrust] * 2),
                                np.column_stack([flap, flap]), np.zeros((N, 2)), None,
                                thrust, None)
    assert ra.low_band_balance(offset, 0)["com_arm_mm"] == pytest.approx(2.0, rel=1e-2)
    common = ra.low_band_common(_signals(torque, moment, flap))
    assert common["flapping"] == pytest.approx(4e-8, rel=1e-3)
    assert common["residual_rms"][0] == pytest.approx(0.0, abs=1e-9)
    g, c = ra.windowed_gain(_signals(torque, 0.3 * torque + 3e-8 * flap, flap), 0)
    assert g == pytest.approx(0.3, rel=1e-6)
    assert c == pytest.approx(3e-8, rel=1e-6)


def test_windowed_heldout_scores_against_holding_the_rate():
    """A balance fitted where M = 0.3 tau + 3e-8 f predicts a held-out log built alike exactly
    (ratio 0); for a log with M' = 0.15 tau + 1.5e-8 f the prediction is 2 M', its error M':
    exactly as bad as holding the rate (ratio 1)."""
    t, f = _noise(18), _noise(19, 1e3)
    train = _signals(t, 0.3 * t + 3e-8 * f, f)
    t2, f2 = _noise(20), _noise(21, 1e3)
    same = _signals(t2, 0.3 * t2 + 3e-8 * f2, f2)
    half = _signals(t2, 0.15 * t2 + 1.5e-8 * f2, f2)
    (g, c), ratios = ra.windowed_heldout([train], [same, half], 0)
    assert g == pytest.approx(0.3, rel=1e-6)
    assert ratios[0] == pytest.approx(0.0, abs=1e-6)
    assert ratios[1] == pytest.approx(1.0, rel=1e-6)


def test_low_band_pooled_reads_each_axis_its_own_coefficient():
    """Three logs built with roll 0.9e-7 and pitch 1.3e-7 below 2 Hz (M = tau + c f, each log
    its own offset): the pooled fit returns each axis' own c, per log the same, and a
    jackknife interval of zero width (the balance is exact)."""
    logs = []
    for k in range(3):
        torque, flap = _noise(30 + k), _noise(40 + k, 1e3)
        moment = np.column_stack([torque + 0.9e-7 * flap, torque + 1.3e-7 * flap]) + 1e-5 * k
        logs.append(ra.RotationSignals(f"log{k}", np.column_stack([torque, torque]), moment,
                                       np.column_stack([flap, flap]), np.zeros((N, 2)), None,
                                       np.zeros(N), None))
    roll, pitch = ra.low_band_pooled(logs, 0), ra.low_band_pooled(logs, 1)
    assert roll["flapping"] == pytest.approx(0.9e-7, rel=1e-3)
    assert pitch["flapping"] == pytest.approx(1.3e-7, rel=1e-3)
    assert pitch["per_log"] == pytest.approx([1.3e-7] * 3, rel=1e-2)
    assert roll["ci"] == pytest.approx(0.0, abs=1e-10) and roll["logs"] == 3


def test_flapping_effect_file_adds_both_axes_with_sources(tmp_path):
    from quadsim.core.errors import InputError
    from quadsim.effects.effectfile import load_effect_file

    base = tmp_path / "d1.toml"
    base.write_text('schema = "quadsim.effects/1"\nparams = "crazyflie21"\n\n[[effect]]\n'
                    'name = "rotor_drag"\ncoefficient = { value = 2.8e-06, unit = "kg/rad", '
                    'source = "gap" }\n')
    pooled = {"roll": {"flapping": 9.1e-8, "ci": 1e-8}, "pitch": {"flapping": 1.31e-7, "ci": 2e-8}}
    out = tmp_path / "d2.toml"
    out.write_text(ra.flapping_effect_file(base, pooled, [tmp_path / "a_run1.csv.gz"]))
    model = load_effect_file(out)
    rotor_drag, flapping = model.effects.effects
    assert rotor_drag.coefficient == 2.8e-06
    assert model.sources[("rotor_drag", "coefficient")] == "gap"
    assert flapping.axes == (9.1e-8, 1.31e-7)
    assert "a_run1.csv.gz" in model.sources[("blade_flapping", "pitch")]
    with pytest.raises(InputError, match="already in it"):
        ra.flapping_effect_file(out, pooled, [])


def test_flapping_effect_file_leaves_out_an_axis_the_estimator_refuses(tmp_path):
    """One estimator (quadsim.identify.flapping): an axis below its acceptance is not written;
    none accepted: refused, the reasons named."""
    from quadsim.core.errors import InputError
    from quadsim.effects.effectfile import load_effect_file

    base = tmp_path / "d1.toml"
    base.write_text('schema = "quadsim.effects/1"\nparams = "crazyflie21"\n')
    pooled = {"roll": {"flapping": 9.1e-8, "ci": 1e-8, "identified": True, "why": ""},
              "pitch": {"flapping": 1e-9, "ci": 2e-8, "identified": False,
                        "why": "blade flapping pitch not identified: includes 0"}}
    out = tmp_path / "d2.toml"
    out.write_text(ra.flapping_effect_file(base, pooled, [tmp_path / "a_run1.csv.gz"]))
    (flapping,) = load_effect_file(out).effects.effects
    assert flapping.axes == (9.1e-8, 0.0)
    pooled["roll"]["identified"] = False
    pooled["roll"]["why"] = "blade flapping roll not identified: 2 log(s)"
    with pytest.raises(InputError, match="roll not identified: 2 log.*pitch not identified"):
        ra.flapping_effect_file(base, pooled, [])


def test_low_band_pooled_is_the_package_estimator():
    """low_band_pooled's value, interval and acceptance are quadsim.identify.flapping's on the
    same signals; two logs: no interval, not identified."""
    from quadsim.identify.flapping import flapping_estimate, flapping_part

    logs = []
    for k in range(4):
        torque, flap = _noise(50 + k), _noise(60 + k, 1e3)
        moment = np.column_stack([torque + (0.9 + 0.05 * k) * 1e-7 * flap] * 2)
        logs.append(ra.RotationSignals(f"log{k}", np.column_stack([torque, torque]), moment,
                                       np.column_stack([flap, flap]), np.zeros((N, 2)), None,
                                       np.zeros(N), None))
    got = ra.low_band_pooled(logs, 0)
    est = flapping_estimate([flapping_part(s.name, s.torque[:, 0], s.moment[:, 0],
                                           s.flapping[:, 0], ra.RATE_HZ) for s in logs], "roll")
    assert got["flapping"] == pytest.approx(est.value, rel=1e-3)
    assert got["ci"] == pytest.approx(0.5 * (est.ci95[1] - est.ci95[0]), rel=1e-2)
    assert got["identified"] and got["ci"] > 0
    two = ra.low_band_pooled(logs[:2], 0)
    assert not two["identified"] and np.isnan(two["ci"]) and "jackknife needs 3" in two["why"]
