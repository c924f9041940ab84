"""The held-out command map against the bare set in the form the training flights show: the
set's own shape (:func:`quadsim.gap.residual.fit_set_map`) or a line
(:func:`quadsim.gap.residual.fit_command_map`, :func:`quadsim.gap.diagnose.training_map`), and a
command model that reads a map in its own unit (:class:`quadsim.gap.logcheck.MapCommandModel`).

crazyflie21's ``[motor_map]`` declares a battery-voltage law (0.249 1/V about 3.7104 V):
``quadsim.fly`` logs the command that gives the commanded speed through it, so the speed per
command rises 3.7 % over a 0.15 V sag while nothing changed. A map fitted as a line in the
command alone reads that law as a ``battery_sag``; the set's own map with a per-rotor gain and
offset does not, and a sag beyond the law (a ``battery_sag`` effect flown) is still named.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.effects import make_effect
from quadsim.gap import diagnose
from quadsim.gap.logcheck import MapCommandModel
from quadsim.gap.residual import (
    FlightStates,
    command_speed,
    fit_command_map,
    fit_motor_map,
    fit_set_map,
    map_misfit,
)
from quadsim.vehicle.params import load_params


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _states(params, volts: np.ndarray, speed_of, seed: int) -> FlightStates:
    """A 20 s, 100 Hz flight: commands 0.42 +- 0.06 (slow sines, one phase per rotor), its
    logged voltages ``volts`` (N,), its speeds ``speed_of(command, volts)`` (N, R)."""
    t = np.arange(0.0, 20.0, 0.01)
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi, 4)
    u = 0.42 + 0.06 * np.sin(2 * np.pi * 0.3 * t[:, None] + phase)
    w = speed_of(u, volts)
    n = len(t)
    z3, quat = np.zeros((n, 3)), np.tile([1.0, 0, 0, 0], (n, 1))
    return FlightStates(t, z3, z3, z3, quat, z3, z3, z3, w, np.zeros_like(w), u, volts,
                        "kinematics", 0.1, 2)


def test_set_map_takes_a_gain_and_offset_on_the_sets_own_law(cf):
    """Speeds 1.05 x the set's map at the logged voltage plus 20 rad/s (the set's table
    a + k u times 1 + 0.249 (v - 3.7104), voltage 4.2 -> 4.05 V): the fitted map's table is
    20 + 1.05 table (the offset read through the law, so to the law's factor: within
    20 x 0.249 x 0.5 V = 2.5 rad/s of it) and its commanded speeds follow the flight to that
    error; the set's own speeds give the set's table back (gain 1, offset 0, to round-off).
    A line in the command alone leaves the law's 3.7 % over the sag on the speeds."""
    mm = cf.motor_map
    volts = np.linspace(4.2, 4.05, 2000)
    own = _states(cf, volts, mm.speed_at, 1)
    fitted = fit_set_map([own], cf).motor_map
    np.testing.assert_allclose(fitted.speed, mm.speed, rtol=1e-9, atol=1e-6)
    assert (fitted.reference_voltage, fitted.voltage_gain) == (mm.reference_voltage,
                                                               mm.voltage_gain)
    assert "quadsim.gap" in fitted.source
    moved = _states(cf, volts, lambda u, v: 20.0 + 1.05 * mm.speed_at(u, v), 2)
    fitted = fit_set_map([moved], cf)
    np.testing.assert_allclose(fitted.motor_map.speed, 20.0 + 1.05 * mm.speed, atol=2.5)
    error = command_speed(moved, fitted) - moved.rotor_speed
    assert float(np.max(np.abs(error))) < 2.5
    # the line in the command alone: the law's change over the flight, about 0.249 x 0.15 V
    # of 1400 rad/s = 52 rad/s end to end, is left as a trend of +-(15-30) rad/s
    line = command_speed(moved, fit_motor_map([moved], cf)) - moved.rotor_speed
    assert float(np.max(np.abs(line))) > 10.0


def test_set_map_reads_a_pwm_table_as_the_set_does():
    """physical's map is in PWM (40-140, bending above 120): the fitted map is in unit "1"
    over the table normalised, and on the set's own speeds it is the set's map read at
    ``to_unit`` (gain 1, offset 0)."""
    phys = load_params("physical")
    mm = phys.motor_map
    volts = np.full(2000, 12.0)
    own = _states(phys, volts, lambda u, v: mm.speed_of(mm.to_unit(u)), 3)
    fitted = fit_set_map([own], phys)
    assert fitted.motor_map.command_unit == "1"
    np.testing.assert_allclose(command_speed(own, fitted), own.rotor_speed, rtol=1e-9,
                               atol=1e-6)


def test_map_command_model_reads_normalised_commands_in_the_maps_unit():
    """A command model of a PWM map (physical: 40-140): normalised command 0.5 is PWM 90,
    495.01 rad/s on rotor 1 (the table's value there); before, 0.5 was read as PWM 0.5,
    below the table (0 rad/s)."""
    phys = load_params("physical")
    model = MapCommandModel(phys, 0.0, "test")
    t = np.arange(0.0, 1.0, 0.01)
    speeds = model.speeds(t, np.full((len(t), 4), 0.5), None)
    assert speeds[-1, 0] == pytest.approx(495.01, rel=1e-12)
    np.testing.assert_allclose(speeds[-1], phys.motor_map.speed[:, 5], rtol=1e-12)


def _verdict(cf, effects: list, seeds=(0, 1, 2)) -> dict:
    logs = [synthetic_flight(cf, effects, duration=6.0, seed=s, speed=0.8 + 0.2 * s,
                             commands="fly") for s in seeds]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return diagnose(logs[:-1], cf, holdout=logs[-1:], kstep=False)["verdict"]


def test_heldout_reads_the_sets_voltage_law_as_no_sag(cf):
    """Flights of crazyflie21 as ``quadsim.fly`` logs them (commands through the map's
    voltage law, vbat 4.2 -> 4.05 V), judged held out against the bare set: no
    ``battery_sag`` (a line in the command alone read the law as one)."""
    verdict = _verdict(cf, [])
    assert verdict["outcome"] == "no_significant_gap", verdict["answer"]
    assert verdict["probability"] > 0.99


def test_heldout_names_a_sag_beyond_the_sets_law(cf):
    """The same flights with a ``battery_sag`` flown (speed x V / 4.2 on top of the set's
    law, 10 % thrust in 10 s): ``battery_sag`` named."""
    verdict = _verdict(cf, [make_effect("battery_sag", rate=0.01, full_voltage=4.2)])
    assert verdict["effect"] == "battery_sag", verdict["answer"]
    assert verdict["probability"] > 0.99
    # the rotor channels' gap (13-14 rad/s before) down to their noise (1.5-2.1 rad/s)
    assert verdict["reduction"] > 0.9


def test_command_map_takes_the_form_the_training_flights_show():
    """physical's PWM table (40-140, bending above 120): speeds logged through it are the
    set's map read at ``to_unit`` (the set's form fits them exactly, misfit ~0) and
    ``fit_command_map`` keeps that form; speeds proportional to the command (a speed-
    controlled motor, RotorPy's) are a line that the set's bend cannot follow, so the line
    is kept, and it gives those speeds back exactly."""
    phys = load_params("physical")
    mm = phys.motor_map
    volts = np.full(2000, 12.0)
    own = _states(phys, volts, lambda u, v: mm.speed_of(mm.to_unit(u)), 4)
    chosen = fit_command_map([own], phys)
    assert "the parameter set's map" in chosen.motor_map.source
    assert map_misfit([own], chosen) < 1e-12 * map_misfit([own], fit_motor_map([own], phys))
    ideal = _states(phys, volts, lambda u, v: 1500.0 * u, 5)
    chosen = fit_command_map([ideal], phys)
    assert chosen.motor_map.source.startswith("fitted on the training flights")
    assert map_misfit([ideal], chosen) < map_misfit([ideal], fit_set_map([ideal], phys))
    np.testing.assert_allclose(command_speed(ideal, chosen), ideal.rotor_speed, rtol=1e-9)


def test_map_misfit_is_the_window_means_sum_of_squares(cf):
    """A map 10 rad/s above every logged speed: each of the 4 rotors' window means is off
    by 10 rad/s, over the 2000 - 50 + 1 moving-mean windows of 0.5 s at 100 Hz."""
    volts = np.full(2000, 3.9)
    flight = _states(cf, volts, lambda u, v: cf.motor_map.speed_at(u, v) - 10.0, 6)
    assert map_misfit([flight], cf) == pytest.approx(100.0 * 4 * (2000 - 50 + 1), rel=1e-9)


def test_the_line_replaces_the_sets_form_only_beyond_chance(monkeypatch):
    """Two 20 s flights (19.99 s from first to last sample) of 4 rotors: 2 x 39.98 x 4 =
    319.84 window means each side, so the line is taken where the set's form leaves more
    than F(0.95; 319.84, 319.84) = 1.202 times its
    misfit (closed form from scipy's F quantile), the set's form at 1.15 (a sag leaves
    about as much on either), the line at 1.25 and at 30 (RotorPy's speed-controlled
    motors under crazyflie21's table)."""
    from scipy.stats import f as f_dist

    import quadsim.gap.residual as residual

    phys = load_params("physical")
    mm = phys.motor_map
    volts = np.full(2000, 12.0)
    flights = [_states(phys, volts, lambda u, v: mm.speed_of(mm.to_unit(u)), k) for k in (7, 8)]
    crit = f_dist.ppf(0.95, 2 * 19.99 / 0.5 * 4, 2 * 19.99 / 0.5 * 4)
    assert residual._form_ratio(flights) == pytest.approx(crit, rel=1e-12)
    assert crit == pytest.approx(1.202, abs=5e-3)
    for ratio, form in ((1.15, "the parameter set's map"), (1.25, "fitted on the training"),
                        (30.0, "fitted on the training")):
        def misfit(fl, params, ratio=ratio):
            return ratio if "parameter set's map" in params.motor_map.source else 1.0
        monkeypatch.setattr(residual, "map_misfit", misfit)
        assert form in residual.fit_command_map(flights, phys).motor_map.source, ratio
