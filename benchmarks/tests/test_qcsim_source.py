"""The quadcopter-sim flight source (benchmarks.qcsim_source, qcsim_cases): its DC motor's
steady map, time constant and propeller coupling in closed form, the plus layout against
quadcopter-sim's own torque equations, the frozen case list, and -- with quadcopter-sim
installed (``pip install -e '.[qcsim]'``) -- one short flight pair checked against
quadsim's own rigid-body and rotor model."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.qcsim_cases import (
    motor_alpha,
    motor_time_constant,
)
from benchmarks.qcsim_source import (
    MODEL,
    FlightSpec,
    duty_for,
    hover_speed_of,
    motor_acceleration,
    qcsim_available,
    steady_speed,
    vehicle_params,
)
from quadsim.vehicle.rotors import rotor_wrench


def test_motor_steady_map_closed_form():
    """The DC motor in steady state: k_t (c V - k_e W) / R = d W^2 (relative 1e-10: the
    quadratic root's cancellation), zero acceleration there; duty_for inverts it (1e-12);
    hover (0.65 kg: 221.5 rad/s) needs 5.74 V, a duty of 0.517; the parameter set's motor
    map is that curve."""
    m = MODEL
    c = np.linspace(0.05, 1.0, 20)
    w = steady_speed(c)
    current = (c * m["battery"] - m["k_emf"] * w) / m["resistance"]
    np.testing.assert_allclose(m["k_emf"] * current, m["d"] * w ** 2, rtol=1e-10)
    np.testing.assert_allclose(motor_acceleration(w, c, m["d"], m["motor_inertia"]), 0.0,
                               atol=1e-9)
    np.testing.assert_allclose(duty_for(w), c, rtol=1e-12)
    assert hover_speed_of() == pytest.approx(np.sqrt(0.65 * 9.81 / 1.3e-4), rel=1e-12)
    assert hover_speed_of() == pytest.approx(221.5, abs=0.05)
    assert duty_for(hover_speed_of()) == pytest.approx(5.741 / 11.1, abs=1e-4)
    params = vehicle_params()
    np.testing.assert_allclose(params.motor_map.speed[0], steady_speed(params.motor_map.command))


def test_motor_time_constant_and_propeller_coupling():
    """Linearised at hover the motor's time constant is J / (k_e^2 / R + 2 d W_h) = 21.4 ms,
    x J; a small speed step decays at that rate (RK4-free: the linearised ODE's exponential,
    1 %); a propeller with d x (1 + x) spins (1 + x)^-alpha as fast at the hover duty (the
    definition, 1e-9), alpha 0.028: the motor is mostly back-EMF bound."""
    tau = motor_time_constant()
    assert tau == pytest.approx(0.0214, abs=1e-4)
    assert motor_time_constant(2.0) == pytest.approx(2 * tau, rel=1e-12)
    w_h = hover_speed_of()
    duty = duty_for(w_h)
    slope = (motor_acceleration(w_h + 0.01, duty, MODEL["d"], MODEL["motor_inertia"])
             - motor_acceleration(w_h - 0.01, duty, MODEL["d"], MODEL["motor_inertia"])) / 0.02
    assert -1.0 / slope == pytest.approx(tau, rel=0.01)
    for change in (-0.15, -0.05, 0.05):
        alpha = motor_alpha(change)
        grid = np.linspace(0.0, 1.0, 2001)
        cmd = np.array([np.interp(w_h, steady_speed(grid), grid)])
        ratio = steady_speed(cmd, MODEL["d"] * (1 + change)) / steady_speed(cmd)
        assert ratio[0] == pytest.approx((1 + change) ** -alpha, rel=1e-9)
        assert 0.02 < alpha < 0.04


@pytest.mark.skipif(not qcsim_available(), reason="quadcopter-sim is not installed")
def test_plus_layout_matches_quadcopter_sims_torques():
    """quadsim's rotor model of the parameter set (rotors on -y, +x, +y, -x; 2 and 4
    clockwise) gives the force and torques of quadcopter-sim's derivative() for random rotor
    speeds (at rest, level: its acceleration x m + g and angular acceleration x I; 1e-12)."""
    from quadcopter.dynamics import Params, derivative

    params = vehicle_params()
    p = Params()
    y = np.zeros(13)
    y[6] = 1.0
    rng = np.random.default_rng(3)
    for speeds in rng.uniform(100.0, 400.0, (5, 4)):
        dy = derivative(0.0, y, speeds, p)
        force, torque = rotor_wrench(params, speeds)
        assert (dy[5] + p.g) * p.m == pytest.approx(force[2], rel=1e-12)
        np.testing.assert_allclose(p.I @ dy[10:13], torque, rtol=1e-12, atol=1e-15)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases, mapped to the library on top of the shared motor lag and body
    drag, within the table's ranges, the payload 30-100 g
    (``_helpers.check_motor_case_list``)."""
    from benchmarks import qcsim_cases
    from benchmarks.tests._helpers import check_motor_case_list

    check_motor_case_list(qcsim_cases, ("motor_lag", "body_drag"), MODEL["mass"],
                          MODEL["arm"], payload_kg=(0.03, 0.1))


@pytest.mark.skipif(not qcsim_available(), reason="quadcopter-sim is not installed")
def test_flights_agree_with_quadsims_model():
    """A nominal flight (2.1 s logged) and a +0.1 kg flight (0.5 s), one process, checked by
    ``_helpers.check_source_flight`` against quadsim's model with the shared motor lag and
    body drag; the mean speed per duty follows the steady map (3 %)."""
    from benchmarks.qcsim_cases import shared_effects
    from benchmarks.qcsim_source import qcsim_flights
    from benchmarks.tests._helpers import check_source_flight

    base = FlightSpec(seed=5, speed=0.8, duration=2.1)
    heavy = FlightSpec(seed=6, speed=0.8, duration=0.5, effects={"mass": 0.1})
    (log, truth), (log_heavy, _) = qcsim_flights([base, heavy], workers=1)
    assert truth["effects"] == {} and truth["source"] == "quadcopter-sim"
    check_source_flight(log, log_heavy, vehicle_params(), 0.1, shared_effects(), MODEL["arm"])
    ratio = np.mean(log.rotor_speed) / np.mean(steady_speed(log.rotor_command))
    assert ratio == pytest.approx(1.0, rel=0.03)
