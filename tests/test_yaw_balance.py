"""The yaw-balance fits behind models/crazyflie21.toml's d (scripts/identify_crazyflie.py
--yaw-balance; docs/identification.md, "What the crazyflie21 flights say about d")."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from _helpers import load_script

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared/data/crazyflie21_brushless"


def _script():
    return load_script("identify_crazyflie")


def test_band_keeps_exactly_the_components_inside_it():
    script = _script()
    dt, n = 0.002, 5000                      # 10 s: whole cycles of 0.3, 1 and 7 Hz
    t = np.arange(n) * dt
    slow, mid, fast = (np.sin(2 * np.pi * f * t) for f in (0.3, 1.0, 7.0))
    out = script._band((3.0 + slow + mid + fast)[:, None], dt, (0.5, 2.0))
    np.testing.assert_allclose(out[:, 0], mid, atol=1e-9)


def _closed_loop(seed: int):
    """A yaw loop that trims a slow unmodelled torque: Izz wdot = d x + q, with x = -q/d below
    the loop's band (so wdot ~ 0 there) plus an excitation that moves the body above it;
    x measured with noise, z the noise-free instrument."""
    rng = np.random.default_rng(seed)
    dt, n, d = 0.002, 20000, 2.0
    t = np.arange(n) * dt
    q = 3.0 * np.sin(2 * np.pi * 0.1 * t)                     # slow disturbance, trimmed
    drive = np.sin(2 * np.pi * 1.5 * t) + 0.5 * np.sin(2 * np.pi * 4.0 * t)
    x_true = -q / d + drive
    y = d * x_true + q + 0.05 * rng.standard_normal(n)         # = d drive + noise
    x = x_true + 0.3 * rng.standard_normal(n)
    return [(y, x[:, None], x_true[:, None], dt)], d


def test_iv_undoes_the_noise_on_the_regressor_and_the_trim_band_pulls_the_pooled_fit_low():
    script = _script()
    rows, d = _closed_loop(1)
    whole = (0.0, float("inf"))
    iv = script._fit(rows, (), whole, "IV")
    ls = script._fit(rows, (), whole, "LS")
    # the slow trim (x moves, y does not) is in var(x), not in cov(x, y): the pooled slope is
    # d var(drive) / var(x) = d 0.625 / (1.125 + 0.625), and least squares adds the noise's
    # 0.09 to the denominator
    assert iv.d == pytest.approx(d * 0.625 / 1.75, rel=0.02)
    assert ls.d == pytest.approx(d * 0.625 / 1.84, rel=0.02)
    # above the trim band the balance holds and the instrument recovers d
    above = script._fit(rows, (), (1.0, 8.0), "IV")
    # its 95 % half-width: the instrument (two sinusoids) sees the noise u = e_y - d e_x at
    # their frequencies only, so 1.96 sqrt(var(u) / (N var(z))), var(u) = 0.05^2 + 4 0.3^2
    half = 0.5 * (above.d_ci95[1] - above.d_ci95[0])
    assert half == pytest.approx(1.96 * np.sqrt(0.3625 / (20000 * 0.625)), rel=0.3)
    assert abs(above.d - d) < 2 * half
    # least squares on the noisy regressor is attenuated by var(x) / (var(x) + var(noise))
    noisy = script._fit(rows, (), (1.0, 8.0), "LS")
    attenuation = 0.625 / (0.625 + 0.09 * 7.0 / 250.0)         # in-band noise share 7/250 Hz
    assert noisy.d == pytest.approx(d * attenuation, rel=0.02)


@pytest.mark.skipif(not (DATA / "nominal").is_dir(), reason="shared data absent")
def test_the_nominal_flights_fix_no_constant_d():
    """The numbers docs/identification.md quotes: whole band 1.51 mm x b (FM > 1), below
    0.5 Hz ~0.2 mm x b, 0.5-2 Hz 2.5 mm x b, 1-16 Hz 3.7 mm x b (d alone, IV)."""
    script = _script()
    fits = script.yaw_balance(sorted((DATA / "nominal").glob("flight_*.csv.gz")),
                              ROOT / "models/crazyflie21.toml", models=((),))
    b = 3.7028e-8
    ratio = {f.band: 1e3 * f.d / b for f in fits if f.method == "IV"}
    assert ratio[(0.0, float("inf"))] == pytest.approx(1.51, abs=0.02)
    assert abs(ratio[(0.0, 0.5)]) < 0.3
    assert ratio[(0.5, 2.0)] == pytest.approx(2.51, abs=0.03)
    assert ratio[(1.0, 16.0)] == pytest.approx(3.71, abs=0.03)
