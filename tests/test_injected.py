"""Changes written into real logs (benchmarks.injected): the closed forms they promise, on a
generated log of the crazyflie21 set (its per-rotor map, battery-voltage law and time
constant), and the scoring rule."""
from dataclasses import replace

import numpy as np
import pytest

from benchmarks.injected import (
    Change,
    commands_for,
    grid,
    injected,
    score,
    speeds_later,
    speeds_with_mass,
    speeds_with_rotor,
)
from benchmarks.synthetic import commands_through_map, synthetic_flight
from quadsim.vehicle.params import load_params
from quadsim.vehicle.rotors import allocation_matrix


@pytest.fixture(scope="module")
def flight():
    params = load_params("crazyflie21")
    log = commands_through_map(synthetic_flight(params, [], seed=3, duration=4.0), params)
    return params, log


def test_a_mass_scales_the_collective_thrust_and_adds_no_torque(flight):
    params, log = flight
    added = 0.003
    new = injected(log, params, Change("mass", added))
    a = allocation_matrix(params)
    before, after = np.square(log.rotor_speed) @ a.T, np.square(new.rotor_speed) @ a.T
    np.testing.assert_allclose(after[:, 2], before[:, 2] * (1 + added / params.mass),
                               rtol=1e-12)
    np.testing.assert_allclose(after[:, 3:], before[:, 3:], atol=1e-12 * np.abs(before).max())
    np.testing.assert_array_equal(new.body_rate, log.body_rate)      # the motion as logged
    np.testing.assert_array_equal(new.accel, log.accel)


def test_a_weaker_propeller_gives_the_logged_wrench_at_its_own_factor(flight):
    params, log = flight
    speed = speeds_with_rotor(log.rotor_speed, 3, -0.08)
    a = allocation_matrix(params)
    factor = np.array([1.0, 1.0, 0.92, 1.0])
    np.testing.assert_allclose(np.square(speed) * factor @ a.T,
                               np.square(log.rotor_speed) @ a.T, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(speed[:, [0, 1, 3]], log.rotor_speed[:, [0, 1, 3]])


def test_the_commands_move_through_the_map_by_the_led_speed_change(flight):
    """map(c', v) - map(c, v) = d + tau d', the steady speed change the command model needs
    (it lags by tau), at the logged battery voltage."""
    params, log = flight
    mm = params.motor_map
    speed = speeds_with_mass(log.rotor_speed, params, 0.002)
    command = commands_for(log, params, speed)
    delta = speed - log.rotor_speed
    led = delta + mm.time_constant * np.gradient(delta, log.t, axis=0)
    np.testing.assert_allclose(mm.speed_at(command, log.vbat) - mm.speed_at(log.rotor_command,
                                                                            log.vbat),
                               led, rtol=1e-9, atol=1e-9)


def test_none_is_the_log_itself_and_scores(flight):
    params, log = flight
    assert injected(log, params, Change("none")) is log
    plain = {"outcome": "no_significant_gap", "verdict": "no_significant_gap"}
    assert score(Change("none"), plain)["right"]
    heavy = {"outcome": "effect", "verdict": "mass_offset", "tentative": False,
             "params": {"mass_offset.mass": 0.0021}}
    assert score(Change("mass", 0.002), heavy)["right"]
    assert not score(Change("mass", 0.004), heavy)["right"]        # 2.1 g for 4 g: off
    assert score(Change("mass", 0.004), heavy)["confident_wrong"]
    assert score(Change("none"), heavy)["confident_wrong"]
    weak = {"outcome": "effect", "verdict": "thrust_mismatch", "tentative": True,
            "params": {"thrust_mismatch.rotor_2": -0.09}}
    assert score(Change("rotor", -0.10, 2), weak)["right"]
    assert not score(Change("rotor", -0.10, 3), weak)["right"]
    assert not score(Change("rotor", -0.10, 3), weak)["confident_wrong"]   # tentative


def test_a_logging_delay_reads_each_stretch_later_and_keeps_the_commands(flight):
    """A ramp logged d later is the ramp at t - d (the first d held at its first value), each
    airborne stretch alone; the commands stay as sent."""
    params, log = flight
    n = len(log.t)
    ramp = np.stack([100.0 + 50.0 * log.t + 10.0 * i for i in range(4)], -1)
    two = replace(log, rotor_speed=ramp, segments=(n // 2,))
    later = speeds_later(two, 0.01)
    for a, b in ((0, n // 2), (n // 2, n)):
        t = log.t[a:b]
        inside = t - 0.01 >= t[0]
        expected = 100.0 + 50.0 * (t[inside] - 0.01)
        np.testing.assert_allclose(later[a:b][inside, 0], expected, rtol=1e-12)
        np.testing.assert_allclose(later[a:b][~inside, 0], ramp[a, 0])    # held, not read
    new = injected(two, params, Change("delay", 0.01))
    np.testing.assert_array_equal(new.rotor_command, two.rotor_command)


def test_every_propeller_weaker_keeps_the_logged_wrench_at_its_factor(flight):
    params, log = flight
    new = injected(log, params, Change("propeller", -0.08))
    a = allocation_matrix(params)
    np.testing.assert_allclose(0.92 * np.square(new.rotor_speed) @ a.T,
                               np.square(log.rotor_speed) @ a.T, rtol=1e-12, atol=1e-15)


def test_the_grid_and_the_scores_of_a_delay_and_a_propeller_set():
    changes = grid({"mass": [0.002], "rotor": [-0.05], "delay": [0.01]}, 5)
    assert [c.label for c in changes[1]] == ["none", "mass +2.0 g", "rotor 2 -5 %",
                                             "rotor delay +10 ms"]
    assert changes[4][2].rotor == 1                                   # 1 + 4 mod 4
    late = {"outcome": "effect", "verdict": "signal_delay", "tentative": True,
            "params": {"delay.rotor": 0.0085}}
    assert score(Change("delay", 0.01), late)["right"]
    assert not score(Change("delay", 0.02), late)["right"]        # 8.5 ms for 20: off
    weak = {"outcome": "effect", "verdict": "mass_offset", "tentative": True,
            "params": {"mass_offset.mass": 0.003}, "readings": ["mass_offset", "thrust_factor"],
            "posterior": [{"name": "mass_offset", "params": {"mass_offset.mass": 0.003}},
                          {"name": "thrust_factor", "params": {"thrust_factor.change": -0.07}}]}
    got = score(Change("propeller", -0.08), weak)
    assert not got["right"] and got["stated"] and not got["confident_wrong"]


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    """A missing flight, an unknown parameter set or a data folder without the labels: one
    `error:` line naming it, exit 2, nothing judged."""
    from benchmarks.injected import main

    none = str(tmp_path / "none.csv.gz")
    assert main(["--flights", none, "--reference", none]) == 2
    assert main(["--model", "no_such_set", "--flights", none, "--reference", none]) == 2
    assert main(["--data", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("error: ") for line in err)
    assert "none.csv.gz: no such file" in err[0]
    assert "no_such_set" in err[1]
    assert "mixed_labels.json: not found" in err[2]


def test_held_out_needs_three_flights(flight, tmp_path, capsys):
    from benchmarks.injected import main
    from quadsim.logs.flightlog import write_log

    params, log = flight
    paths = [str(write_log(tmp_path / f"f{k}.csv.gz", log)) for k in range(2)]
    assert main(["--mode", "held-out", "--flights", *paths, "--reference", *paths]) == 2
    assert capsys.readouterr().err.startswith("error: --flights: held out needs 3 flights")


def test_the_answers_feed_the_reliability_table():
    """benchmarks.reliability --injected: each answer's stated probability and "named" as
    right; the library-only probability where given, else the stated one; a JSON without
    answers refused naming the field."""
    from benchmarks.reliability import injected_answers, reliability_table

    rows = [{"flight": "f.csv.gz", "change": "mass +2.0 g", "outcome": "effect",
             "verdict": "thrust_factor", "probability": 0.95,
             "probability_within_library": 0.97, "right": False},
            {"flight": "f.csv.gz", "change": "none", "outcome": "no_significant_gap",
             "verdict": "no_significant_gap", "probability": 0.99, "right": True}]
    answers = injected_answers({"answers": rows})
    assert [(a.truth, a.stated, a.within, a.right) for a in answers] == [
        ("mass +2.0 g", 0.95, 0.97, False), ("none", 0.99, 0.99, True)]
    table = {r.label: r for r in reliability_table(answers)}
    assert table["0.9-0.99"].answers == 1 and table["0.9-0.99"].fraction_right == 0.0
    with pytest.raises(ValueError, match="answers"):
        injected_answers({"flights": []})
