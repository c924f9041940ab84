"""A battery sag on logs with motor commands only (IMU, pose and commands; rotor speeds
synthesised from the commands, quadsim.gap.logcheck): the speeds the commands give fall as
the battery drains, beyond what the references' map (and its voltage law) says.

Before, the synthesised speeds were read as measured ones, on which an effect upstream of
the speed does not act, so no battery reading was offered on such a log: the report's 0.84 kg
testbed losing 1 % of its thrust per second (``benchmarks.campaigns --campaign testbed --logs
commands``) was ``unexplained`` after a thrust factor (Fz 10x). Now the reading scales the
synthesised speeds by its time law, sqrt(1 - rate (t - t_0))
(:func:`quadsim.gap.fitting.upstream_speeds`).

Generated closed-loop flights (crazyflie21, MuJoCo, sensor noise), 4 references and 2
flights of 6 s, commands and battery voltage logged, no rotor speeds.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from quadsim.effects import make_effect
from quadsim.gap.fitting import SpeedGain, residuals, upstream_speeds
from quadsim.logs.sensors import SensorModel

from _helpers import commands_only_flight, crazyflie_without_lag, judge_commands_only

NOISE = SensorModel(noise={"position": 5e-4, "velocity": 0.01, "attitude": 2e-3,
                           "gyro": 0.02, "accel": 0.1, "rotor": 10.0})
PATHS = ("figure8", "steps", "lissajous", "figure8")
RATE = 0.01         # 1/s: thrust at a fixed command falls 1 % per second (6 % over the flight)

pytestmark = pytest.mark.xdist_group("test_commands_sag")


@pytest.fixture(scope="module")
def cf():
    return crazyflie_without_lag()


def _commands_only(cf, effects, seed, path="figure8"):
    return commands_only_flight(cf, effects, NOISE, seed, path, duration=6.0)


@pytest.fixture(scope="module")
def judged(cf):
    refs = [_commands_only(cf, (), seed, path) for seed, path in enumerate(PATHS)]
    flights = {"calm": _commands_only(cf, (), 21),
               "sag": _commands_only(cf, (make_effect("battery_sag", rate=RATE),), 22)}
    return judge_commands_only(cf, refs, flights)


def test_a_sag_on_a_command_only_log_is_named_with_its_rate(judged):
    verdict = judged["sag"]
    assert verdict["outcome"] == "effect" and verdict["readings"] == ["battery_sag"]
    rate, ci = verdict["params"]["battery_sag.rate"], verdict["ci"]["battery_sag.rate"]
    assert abs(rate - RATE) < max(2 * ci, 0.1 * RATE)
    assert verdict["probability"] > 0.9


def test_a_calm_command_only_flight_stays_clear(judged):
    verdict = judged["calm"]
    assert verdict["outcome"] == "no_significant_gap"
    reading = next(p for p in verdict["posterior"] if p["name"] == "battery_sag")
    assert reading["params"]["battery_sag.rate"] < 0.1 * RATE


def test_the_sag_scales_only_synthesised_speeds(judged, cf):
    """The time law on the synthesised states' speeds, sample by sample; measured speeds
    (the same states not marked synthesised) are read as logged."""
    states = judged["prepared"][0].fit
    assert states.synthesised
    sag = make_effect("battery_sag", rate=RATE)
    scaled = upstream_speeds(states, [sag])
    expected = states.rotor_speed * np.sqrt(1.0 - RATE * (states.t - states.t[0]))[:, None]
    np.testing.assert_allclose(scaled, expected, rtol=1e-12)
    measured = dataclasses.replace(states, synthesised=False)
    assert upstream_speeds(measured, [sag]) is None
    # the references' map gain is in the synthesis already: not applied again
    assert upstream_speeds(states, [SpeedGain(gain=0.05)]) is None
    # the wrench reads the scaled speeds: the residual moves on a synthesised log only
    plain = residuals(states, cf, [], rotor_channel=False)
    assert np.abs(residuals(states, cf, [sag], rotor_channel=False) - plain).max() > 1e-4
    np.testing.assert_array_equal(residuals(measured, cf, [sag], rotor_channel=False),
                                  residuals(measured, cf, [], rotor_channel=False))
