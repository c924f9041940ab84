"""The commands ``quadsim.fly`` logs (``quadsim.logs.generate.logged_command``): a parameter set
with a motor map logs the command its own map gives for the commanded speed, at the logged
battery voltage; one without a map logs ``commanded speed / max_speed`` as before, bit for bit.

Closed forms: the crazyflie21 map is a line per rotor, ``Omega_i = a_i + (b_i - a_i) u`` at the
reference voltage v_ref, scaled by ``1 + gamma (v - v_ref)``; so the logged command is
``u_i = (Omega_i / (1 + gamma (v - v_ref)) - a_i) / (b_i - a_i)``. A command-only reading of
such a flight (``quadsim.gap.logcheck``: the speeds removed, synthesised through the set's map
and its time constant) gives back the flown speeds of a vehicle whose motors lag by that time
constant; under the old convention (``speed / max_speed`` read through the map) it read them
52 % too fast (4 s figure-8 at 4.2 V).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import quadsim.logs.generate as generate
from quadsim.core.errors import InputError
from quadsim.effects import EffectSet, make_effect
from quadsim.gap.logcheck import command_model_from_params, synthesise_speeds, without_speeds
from quadsim.gap.residual import command_of_speed, speed_of_command
from quadsim.logs.generate import command_convention, generate_flight, logged_command
from quadsim.vehicle.params import load_params

CF = load_params("crazyflie21")


def _fly(params, effects=(), monkeypatch=None, **kwargs):
    """generate_flight with the engine's trajectory kept (its commanded speeds)."""
    kept = {}
    simulate = generate.simulate

    def keep(*args, **kw):
        kept["traj"] = simulate(*args, **kw)
        return kept["traj"]

    monkeypatch.setattr(generate, "simulate", keep)
    log, truth = generate_flight(params, "figure8", EffectSet(tuple(effects)), None, 0,
                                 duration=kwargs.pop("duration", 3.0), **kwargs)
    return log, truth, kept["traj"]


def test_a_crazyflie21_flight_logs_the_command_its_map_gives(monkeypatch):
    log, truth, traj = _fly(CF, monkeypatch=monkeypatch)
    mm = CF.motor_map
    speed = traj.rotor_command
    np.testing.assert_array_equal(log.vbat, 4.2)          # one full cell, no battery_sag
    factor = 1.0 + mm.voltage_gain * (4.2 - mm.reference_voltage)
    assert factor == pytest.approx(1.121910, abs=1e-6)     # 1 + 0.249 (4.2 - 3.7104)
    a, b = mm.speed[:, 0], mm.speed[:, 1]
    np.testing.assert_allclose(log.rotor_command, (speed / factor - a) / (b - a), rtol=1e-12)
    # back through the gap's own map functions: the commanded speeds, to round-off
    np.testing.assert_allclose(speed_of_command(CF, log.rotor_command) * factor, speed,
                               rtol=1e-12)
    np.testing.assert_allclose(mm.speed_at(log.rotor_command, log.vbat), speed, rtol=1e-12)
    # the flown range of the real flights' commands (0.35-0.49), not speed / max_speed (0.57)
    assert 0.35 < log.rotor_command.min() < log.rotor_command.max() < 0.40
    assert np.all(speed / CF.max_speed > 0.55)
    record = truth["command_map"]
    assert "command_normalisation" not in truth
    assert record["convention"] == "motor_map" and record["vbat_range_v"] == [4.2, 4.2]
    assert record["reference_voltage_v"] == mm.reference_voltage
    assert command_convention(truth)["convention"] == "motor_map"


def test_the_command_follows_the_logged_voltage():
    """A voltage that varies along the log (battery_sag): the closed form sample by sample,
    and the gap's inverse (command_of_speed with the voltages) the same numbers."""
    mm = CF.motor_map
    speed = np.linspace(800.0, 2400.0, 12)[:, None] * np.array([1.0, 1.01, 0.99, 1.02])
    vbat = np.linspace(4.2, 3.3, 12)
    command, record = logged_command(CF, speed, vbat)
    factor = (1.0 + mm.voltage_gain * (vbat - mm.reference_voltage))[:, None]
    a, b = mm.speed[:, 0], mm.speed[:, 1]
    np.testing.assert_allclose(command, (speed / factor - a) / (b - a), rtol=1e-12)
    np.testing.assert_array_equal(command, command_of_speed(CF, speed, vbat))
    assert record["command_map"]["vbat_range_v"] == [3.3, 4.2]
    # without voltages: the map as stated, at its reference voltage
    np.testing.assert_allclose(command_of_speed(CF, speed), (speed - a) / (b - a), rtol=1e-12)


def test_a_pwm_map_logs_its_normalised_command():
    """The physical set's map is in PWM 40-140: 0-1 spans it, through its nonlinear table."""
    phys = load_params("physical")
    mm = phys.motor_map
    speed = np.array([[300.0, 450.0, 600.0, 700.0]])
    command, _ = logged_command(phys, speed, np.full(1, 12.6))
    pwm = 40.0 + 100.0 * command
    for i in range(4):      # the PWM whose table speed is the speed: linear between rows
        k = np.searchsorted(mm.speed[i], speed[0, i])
        lo, hi = mm.speed[i, k - 1], mm.speed[i, k]
        expected = mm.command[k - 1] + 10.0 * (speed[0, i] - lo) / (hi - lo)
        assert pwm[0, i] == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(speed_of_command(phys, command), speed, rtol=1e-12)


def test_a_set_without_a_map_is_unchanged_bit_for_bit(monkeypatch):
    plain = CF.replace(motor_map=None)
    log, truth, traj = _fly(plain, monkeypatch=monkeypatch, duration=2.0)
    np.testing.assert_array_equal(log.rotor_command, traj.rotor_command / plain.max_speed)
    assert truth["command_normalisation"] == {"max_speed": plain.max_speed, "unit": "rad/s"}
    assert "command_map" not in truth
    assert command_convention(truth) == {"convention": "max_speed", "max_speed": 2750.0}


def test_old_sidecars_read_as_speed_over_max_speed():
    """A sidecar written before the map convention (a crazyflie21 one included: its log has
    ``speed / max_speed``) says command_normalisation; one with neither key is refused."""
    old = {"schema": "quadsim.flight-truth/1", "model": "crazyflie21",
           "command_normalisation": {"max_speed": 2750.0, "unit": "rad/s"}}
    assert command_convention(old) == {"convention": "max_speed", "max_speed": 2750.0}
    with pytest.raises(InputError, match="command_normalisation / command_map"):
        command_convention({"schema": "quadsim.flight-truth/1"})


def test_a_command_only_reading_gives_the_flown_speeds(monkeypatch):
    """The speeds removed (logcheck.without_speeds, the command-only path of ``gap``) and
    synthesised from the commands through the set's map and its 50 ms lag, on a vehicle
    whose motors lag by that time constant: within 1e-4 of the logged speeds (the lag's
    discretisation; 1.0e-5 RMS measured). The old convention read 1.52x too fast."""
    lag = make_effect("motor_lag", time_constant=CF.motor_map.time_constant)
    log, _, _ = _fly(CF, (lag,), monkeypatch=monkeypatch, duration=4.0)
    model = command_model_from_params(CF)
    synthesised = synthesise_speeds(without_speeds(log), model).rotor_speed
    relative = np.abs(synthesised - log.rotor_speed) / log.rotor_speed
    assert np.max(relative) < 1e-4
    old = dataclasses.replace(log, rotor_command=log.rotor_speed / CF.max_speed)
    ratio = synthesise_speeds(without_speeds(old), model).rotor_speed / log.rotor_speed
    assert np.median(ratio) == pytest.approx(1.52, abs=0.02)


def test_a_map_without_an_inverse_is_refused_naming_the_field():
    mm = CF.motor_map
    speed = np.array([[0.0, 2000.0, 1500.0]] + [[0.0, 1000.0, 2000.0]] * 3)
    bent = dataclasses.replace(mm, command=np.array([0.0, 0.5, 1.0]), speed=speed)
    with pytest.raises(InputError, match="motor_map.speed: rotor 1's speed falls"):
        logged_command(CF.replace(motor_map=bent), np.full((2, 4), 900.0), np.full(2, 4.2))


def test_a_sag_on_a_three_cell_vehicle_starts_at_its_pack_voltage(monkeypatch):
    """``battery_sag:rate=...`` without a full voltage on the 0.84 kg testbed (3S, 12.6 V): the
    log's voltage starts at the 12.6 V its nominal flights log and falls as
    V_full sqrt(1 - rate t) (thrust ~ V^2), not from the effect's one-cell 4.2 V; a given
    ``full_voltage`` is kept; on a one-cell vehicle the two agree (4.2 V)."""
    phys = load_params("physical")
    sag = make_effect("battery_sag", rate=0.01)
    log, truth, _ = _fly(phys, (sag,), monkeypatch=monkeypatch, duration=2.0)
    np.testing.assert_allclose(log.vbat, 12.6 * np.sqrt(1.0 - 0.01 * log.t), rtol=1e-12)
    assert truth["command_map"]["vbat_range_v"][1] == pytest.approx(12.6, rel=1e-12)
    given = make_effect("battery_sag", rate=0.01, full_voltage=11.1)
    log, _, _ = _fly(phys, (given,), monkeypatch=monkeypatch, duration=1.0)
    assert log.vbat[0] == pytest.approx(11.1, rel=1e-12)
    log, _, _ = _fly(CF, (sag,), monkeypatch=monkeypatch, duration=1.0)
    np.testing.assert_allclose(log.vbat, 4.2 * np.sqrt(1.0 - 0.01 * log.t), rtol=1e-12)
    assert sag.given() == {"rate"} and given.given() == {"rate", "full_voltage"}
