"""The accelerometer check against a noisy velocity (quadsim.logs.checks.check_accel): the
gain of the accelerometer's window means on the velocity differences is an errors-in-variables
(Deming) regression with each side's noise read from the log. With least squares a velocity of
0.03 m/s noise per sample (0.4 m/s^2 on a 0.1 s window's difference) pulled the gain of a sound
generated figure-8 to 0.37 and refused it as "sign or frame wrong?"."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.core.frames import quat_to_rotmat
from quadsim.effects import EffectSet
from quadsim.logs.checks import _deming_gain, _gain, check_accel
from quadsim.logs.flightlog import load_log
from quadsim.logs.generate import generate_flight
from quadsim.logs.sensors import SensorModel
from quadsim.vehicle.params import load_params

PARAMS = load_params("crazyflie21")
NOISY = {"velocity": 0.03, "accel": 0.1, "gyro": 0.01, "attitude": 0.002, "position": 0.001}


def _flight(speed: float, noise: dict):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log, _ = generate_flight(PARAMS, "figure8", EffectSet(), SensorModel(noise=noise), 0,
                                 duration=6.0, speed=speed)
    return log


def test_deming_gain_closed_forms():
    """Exact data y = 2 x give 2 at any noise ratio; ratio inf is least squares; ratio 0
    (the reference alone noisy) is the reverse regression's inverse, s_yy / s_xy; noise on
    the reference alone leaves the Deming gain unbiased where least squares is attenuated by
    s_signal^2 / (s_signal^2 + s_noise^2)."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=4000)
    for ratio in (0.0, 0.3, 1.0, 50.0, np.inf):
        assert _deming_gain(2.0 * x, x, ratio) == pytest.approx(2.0, rel=1e-12)
    y = 2.0 * x + rng.normal(scale=0.3, size=x.size)
    assert _deming_gain(y, x, np.inf) == pytest.approx(_gain(y, x), rel=1e-12)
    noisy_x = x + rng.normal(scale=1.0, size=x.size)
    assert _deming_gain(2.0 * x, noisy_x, 0.0) == pytest.approx(
        np.mean(4.0 * x * x) / np.mean(2.0 * x * noisy_x), rel=1e-12)
    assert _gain(2.0 * x, noisy_x) == pytest.approx(1.0, abs=0.1)      # attenuated: 2 / 2
    assert _deming_gain(2.0 * x, noisy_x, 0.0) == pytest.approx(2.0, abs=0.1)
    # both noisy, at their variance ratio (0.3^2 / 1.0^2): unbiased
    assert _deming_gain(y, noisy_x, 0.09) == pytest.approx(2.0, abs=0.1)


@pytest.mark.parametrize("speed", [0.3, 1.0])
def test_a_sound_log_with_a_noisy_velocity_passes(speed):
    """A generated figure-8 at 0.3 and 1.0 m/s, velocity noise 0.03 m/s per sample: passed
    (least squares read 0.004 and 0.37 on world x and refused both)."""
    log = _flight(speed, NOISY)
    check_accel(log)


def test_the_accelerometer_in_g_and_in_the_world_frame_are_still_refused():
    """The same noisy flight at 1.0 m/s with the accelerometer in g (gain ~0.10, named) and
    logged in the world frame and turned again (the tilt doubled: gain ~2 on world x) is
    refused in one line naming the axis."""
    log = _flight(1.0, NOISY)
    with pytest.raises(InputError, match=r"a[xyz]: accelerometer rotated to the world frame = "
                                         r"0\.1\d* x .*in g instead of m/s\^2\?"):
        check_accel(dataclasses.replace(log, accel=log.accel / 9.81))
    world = np.einsum("nij,nj->ni", quat_to_rotmat(log.quat), log.accel)
    with pytest.raises(InputError, match=r"ax: accelerometer rotated to the world frame = "
                                         r"(1\.[6-9]|2\.[0-4])\d* x .*frame"):
        check_accel(dataclasses.replace(log, accel=world))


def test_a_smooth_velocity_keeps_least_squares():
    """Without velocity noise the velocity side's noise reads ~0 and the gain is least
    squares' (the check as it was): the noise-free flight passes, in g it is refused."""
    log = _flight(1.0, {})
    check_accel(log)
    with pytest.raises(InputError, match="in g instead"):
        check_accel(dataclasses.replace(log, accel=log.accel / 9.81))


def _held_on_rows(t: np.ndarray, x: np.ndarray, hz: float) -> np.ndarray:
    """``x`` (N, ...) held between samples taken every 1 / ``hz`` s (a motion-capture pose on
    faster rows)."""
    rows = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], 1.0 / hz)))
    return x[rows[np.searchsorted(t[rows], t, side="right") - 1]]


def test_a_log_without_velocity_is_checked_on_its_smoothed_position():
    """A generated log with its position only (no velocity column), the position held at
    125 Hz on 500 Hz rows as a motion-capture pose is: the window velocity differences come
    from the position smoothed over 0.05 s and differentiated on the rows' times
    (``checks._position_velocity``): the sound log passes, the world-frame accelerometer is
    still refused."""
    log = _flight(1.0, {"accel": 0.1, "gyro": 0.01, "position": 0.001})
    held = dataclasses.replace(log, position=_held_on_rows(log.t, log.position, 125.0),
                               velocity=None)
    check_accel(held)
    world = np.einsum("nij,nj->ni", quat_to_rotmat(held.quat), held.accel)
    with pytest.raises(InputError, match="frame"):
        check_accel(dataclasses.replace(held, accel=world))


MIXED = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazyflie21_brushless"


@pytest.mark.skipif(not MIXED.exists(), reason="needs ../shared/data")
@pytest.mark.parametrize("name", ["mixed/flight_105.csv.gz", "mixed/flight_121.csv.gz",
                                  "nominal/flight_14.csv.gz"])
def test_real_flights_without_their_velocity_pass(name):
    """Real Crazyflie flights with the velocity column dropped (their pose held at 100-175 Hz
    on ~500 Hz rows), airborne as ``gap`` cuts them: they pass the check, and with their
    accelerometer turned to the world frame they are refused. The sample-to-sample gradient
    of the held position refused 16 of the 46 Crazyflie flights so, these three among them
    (flight 105: 1.97 x on world y); one is refused now (flight 102, across its logging
    gaps)."""
    from quadsim.logs.spans import join_airborne

    log, _ = join_airborne(load_log(MIXED / name, warn=False))
    bare = dataclasses.replace(log, velocity=None)
    check_accel(bare)
    world = np.einsum("nij,nj->ni", quat_to_rotmat(bare.quat), bare.accel)
    with pytest.raises(InputError, match="frame"):
        check_accel(dataclasses.replace(bare, accel=world))
