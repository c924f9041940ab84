"""The rotor-order check reads the commands through the motors' lag (quadsim.logs.checks.
commands_lag): a command leads the speed it gives by the motor's time constant, and read as
logged that lead is a model error of the torque balance that a rival column order can fit.

Generated flights of PX4 SITL's jMAVSim X quad (``px4_sitl_iris``: no motor map, commands
are speed / max_speed) whose motors lag by 30 ms, rotor speeds with 8 rad/s of noise (too
noisy to tell an order: the commands are the signal read), 100 Hz, 8 s: a lissajous in the
right order was doubtful (``--rotor-map 4,1,2,3``: Delta chi^2 19.7; the campaign's 15 s
one was refused at 63.4, ``benchmarks.campaigns --campaign xquad``); through the lag the
check fits (20 ms) no rival comes above 0.8. A figure-8 with rotors 1 and 3 swapped in
both signals is refused as before, more firmly (246 -> 271).
"""

from __future__ import annotations

import dataclasses

import pytest

from _helpers import lagging_flight

pytestmark = pytest.mark.xdist_group("test_order_lag")


def _flight(path: str, seed: int, speed: float):
    return lagging_flight("px4_sitl_iris", 1e-5, 0.03, {"gyro": 0.01, "accel": 0.05,
                                                        "rotor": 8.0, "position": 0.001},
                          100.0, seed, path, duration=8.0, speed=speed, height=2.0, size=2.0)


def test_a_lagging_motor_does_not_doubt_the_right_order():
    from quadsim.logs.checks import (
        DOUBT_CHI2,
        commands_lag,
        rotor_order_evidence,
        rotor_order_status,
    )

    params, log = _flight("lissajous", 1, 0.84)
    lag = commands_lag(log, params)
    assert 0.015 <= lag <= 0.05                      # the flight's 30 ms, on the check's grid
    status = rotor_order_status(log, params)
    assert status.source == "commands" and not status.doubtful
    assert max(rotor_order_evidence(log, params).values()) < DOUBT_CHI2
    # as logged (no lag) the same balance doubts it: the rival this test guards against
    from quadsim.logs import checks
    from quadsim.vehicle.rotors import allocation_matrix

    rows = allocation_matrix(params)[3:6]
    choice = checks._order_choice(log, params, False)
    assert [name for name, _ in choice] == ["commands"]
    assert checks._against_own(choice[0][1], rows, rows, (3, 0, 1, 2)) > 4 * DOUBT_CHI2


def test_a_true_swap_is_still_refused():
    from quadsim.logs.checks import ORDER_CHI2, rotor_order_evidence

    params, log = _flight("figure8", 2, 1.2)
    swap = [2, 1, 0, 3]                                  # rotors 1 and 3 in both signals
    swapped = dataclasses.replace(log, rotor_speed=log.rotor_speed[:, swap],
                                  rotor_command=log.rotor_command[:, swap])
    assert rotor_order_evidence(swapped, params)[tuple(swap)] > 10 * ORDER_CHI2
