"""Roll/pitch inertia from the band where the rotors drive the body (quadsim.identify.rotation):
on synthetic logs whose rotor torque below 1 Hz balances an unmodelled moment (no angular
acceleration) and whose rotor data lag the state by a per-log delay, the whole-band fit fails
and the band fit returns the inertia the logs were built with."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from quadsim.identify.from_logs import fit_inertia
from quadsim.identify.logseries import Estimate, LogSeries, Skeleton
from quadsim.identify.rotation import band_inertia, with_band_inertia

RATE = 100.0
B = 3.7e-8
L = 0.035
IXX, IYY, IZZ = 2.4e-5, 2.7e-5, 3.2e-5
POS = np.array([[L, -L, 0], [-L, -L, 0], [-L, L, 0], [L, L, 0]], float)
SKELETON = Skeleton(0.045, np.zeros(3), np.array([IXX, IYY, IZZ]), POS,
                    np.array([1.0, -1.0, 1.0, -1.0]), None, "synthetic.toml")


def _band(seed: int, lo: float, hi: float, n: int, scale: float) -> np.ndarray:
    sos = signal.butter(2, (lo, hi), btype="bandpass", fs=RATE, output="sos")
    x = signal.sosfiltfilt(sos, np.random.default_rng(seed).standard_normal(n))
    return scale * x / x.std()


def _log(seed: int, delay_s: float, n: int = 6000) -> LogSeries:
    """Roll/pitch torques: a driving part (2-20 Hz) that accelerates the body, and a 10x larger
    part below 1 Hz that balances a moment the model lacks; the rotor speeds realise the sum
    and are logged ``delay_s`` late."""
    t = np.arange(n) / RATE
    drive = np.column_stack([_band(seed + k, 2.0, 20.0, n, 1e-4) for k in range(2)])
    balance = np.column_stack([_band(seed + 5 + k, 0.05, 1.0, n, 1e-3) for k in range(2)])
    torque = drive + balance
    # rotor speeds with b sum y_i W^2 = roll torque, -b sum x_i W^2 = pitch torque
    base = 1800.0 ** 2
    w2 = np.empty((n, 4))
    tx, ty = torque[:, 0] / (B * L), torque[:, 1] / (B * L)
    # roll = L (-w1 - w2 + w3 + w4), pitch = -L (w1 - w2 - w3 + w4)
    w2[:, 0] = base + (-tx - ty) / 4
    w2[:, 1] = base + (-tx + ty) / 4
    w2[:, 2] = base + (tx + ty) / 4
    w2[:, 3] = base + (tx - ty) / 4
    k = np.arange(n, dtype=float)
    w2 = np.column_stack([np.interp(k - delay_s * RATE, k, c) for c in w2.T])
    accel = np.column_stack([drive[:, 0] / IXX, drive[:, 1] / IYY, np.zeros(n)])
    rate = np.cumsum(accel, axis=0) / RATE
    rate -= signal.sosfiltfilt(signal.butter(2, 0.05, fs=RATE, output="sos"), rate, axis=0)
    rate[:, 2] = _band(seed + 9, 0.05, 0.5, n, 0.1)      # a slow yaw rate: gyroscopic terms
    return LogSeries(f"log{seed}", t, np.zeros((n, 3)), rate, accel, np.sqrt(w2), None, None)


def test_band_fit_recovers_inertia_where_whole_band_fit_fails():
    logs = [_log(10 * s, d) for s, d in ((1, 0.0), (2, 0.0175), (3, -0.01))]
    whole = fit_inertia(logs, SKELETON, B, np.array([1e-5, 1e-5, 1e-5]))
    assert not any(e.identified for e in whole)          # R^2 far below 0.5
    band = band_inertia(logs, SKELETON, B)
    assert band[0].identified and band[1].identified
    assert band[0].value == pytest.approx(IXX, rel=0.03)
    assert band[1].value == pytest.approx(IYY, rel=0.03)
    # rotor data logged 17.5 ms late: the moment leads the logged torque by 17.5 ms
    assert "-0.0, -17.5, +10.0 ms" in band[0].quality
    merged = with_band_inertia(whole, logs, SKELETON, B)
    assert [e.value for e in merged] == [band[0].value, band[1].value]
    assert "the whole-band fit not used" in merged[0].quality


def test_identified_whole_band_estimate_is_kept():
    logs = [_log(40, 0.0)]
    kept = Estimate(2.0e-5, (1.9e-5, 2.1e-5), "whole band")
    merged = with_band_inertia([kept, kept], logs, SKELETON, B)
    assert merged == [kept, kept]


def test_slow_logs_cannot_show_the_band():
    log = _log(50, 0.0)
    slow = LogSeries(log.name, log.t[::4], log.specific_force[::4], log.body_rate[::4],
                     log.body_accel[::4], log.rotor_speed[::4], None, None)   # 25 Hz
    assert band_inertia([slow], SKELETON, B) == [None, None]


def test_band_estimate_on_arrays_is_the_log_fit():
    """``band_parts`` + ``band_estimate`` (the array form a calibration on prepared flight
    states calls) give the same inertia as ``band_inertia`` on the logs, and recover each
    log's lag of the moment behind the torque on the delay grid."""
    from quadsim.identify.rotation import band_estimate, band_parts

    logs = [_log(10 * s, d) for s, d in ((1, 0.0), (2, 0.0175), (3, -0.01))]
    from_logs = band_inertia(logs, SKELETON, B)[0]
    parts = []
    for log in logs:
        w2 = np.square(log.rotor_speed)
        torque = B * (w2 @ POS[:, 1])
        gyro = log.body_rate[:, 1] * log.body_rate[:, 2]
        parts.append(band_parts(torque, log.body_accel[:, 0], gyro, RATE))
    est = band_estimate(parts, "Ixx")
    assert est.identified
    assert est.value == pytest.approx(from_logs.value, rel=1e-12)
    assert est.value == pytest.approx(IXX, rel=0.03)
    # rotor data logged 17.5 ms late, 10 ms early: the moment leads / lags the logged torque
    assert "-17.5, +10.0 ms" in est.quality
    assert band_parts(torque, log.body_accel[:, 0], gyro, 30.0) is None     # below 2.5 x 16 Hz
