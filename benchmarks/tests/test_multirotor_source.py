"""The multirotor flight source (benchmarks.multirotor_source, multirotor_cases): its DC
motor's steady map and propeller coupling in closed form, the frozen case list, and -- with
multirotor installed (``pip install numba`` then ``pip install --no-deps multirotor==0.5.0``)
-- one short flight pair checked against quadsim's own rigid-body and rotor model."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.multirotor_cases import (
    motor_alpha,
    motor_time_constant,
)
from benchmarks.multirotor_source import (
    MODEL,
    FlightSpec,
    multirotor_available,
    steady_speed,
    vehicle_params,
)


def test_steady_speed_closed_form():
    """multirotor's motor in steady state: k_t (c V - k_e W) / R = k_d W^2 (relative 1e-12;
    the steady current stays below the 38 A limit up to full voltage); the parameter set's motor map
    is that curve (its grid points exactly); hover (5.5 kg on 4 rotors: 370 rad/s) sits at
    a voltage fraction 0.47 (10.6 V: k_e W + R k_d W^2 / k_t)."""
    m = MODEL
    c = np.linspace(0.05, 1.0, 20)
    w = steady_speed(c)
    current = (c * m["max_voltage"] - m["k_emf"] * w) / m["resistance"]
    assert np.all(current < m["max_current"])       # 34 A at full voltage: below the limit
    np.testing.assert_allclose(m["k_emf"] * current, m["k_drag"] * w ** 2, rtol=1e-12)
    params = vehicle_params()
    np.testing.assert_allclose(params.motor_map.speed[0], steady_speed(params.motor_map.command))
    hover = np.sqrt(m["mass"] * 9.81 / (4 * m["k_thrust"]))
    volts = m["k_emf"] * hover + m["resistance"] * m["k_drag"] * hover ** 2 / m["k_emf"]
    grid = np.linspace(0, 1, 200001)
    assert np.interp(hover, steady_speed(grid), grid) == pytest.approx(
        volts / m["max_voltage"], rel=1e-6)
    assert hover == pytest.approx(370.2, abs=0.1) and volts == pytest.approx(10.58, abs=0.01)


def test_propeller_coupling_and_motor_time_constant():
    """A propeller with k_d x (1 + x) spins (1 + x)^-alpha as fast at the hover command (the
    definition, relative 1e-9; alpha 0.065 for this motor: a DC motor whose load torque is
    k_d W^2); the linearised time constant J / (k_t k_e / R + 2 k_d W_h) is 5.0 ms and scales
    with J."""
    for change in (-0.15, -0.05, 0.05):
        alpha = motor_alpha(change)
        grid = np.linspace(0.0, 1.0, 2001)
        hover = np.sqrt(MODEL["mass"] * 9.81 / (4 * MODEL["k_thrust"]))
        cmd = np.array([np.interp(hover, steady_speed(grid), grid)])
        ratio = steady_speed(cmd, MODEL["k_drag"] * (1 + change)) / steady_speed(cmd)
        assert ratio[0] == pytest.approx((1 + change) ** -alpha, rel=1e-9)
        assert 0.05 < alpha < 0.08
    assert motor_time_constant() == pytest.approx(4.98e-3, rel=1e-3)
    assert motor_time_constant(2.0) == pytest.approx(2 * motor_time_constant(), rel=1e-12)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases, mapped to the library on top of the shared motor lag and body
    drag, within the table's ranges (``_helpers.check_motor_case_list``)."""
    from benchmarks import multirotor_cases
    from benchmarks.tests._helpers import check_motor_case_list

    check_motor_case_list(multirotor_cases, ("motor_lag", "body_drag"), MODEL["mass"],
                          MODEL["arm"])


@pytest.mark.skipif(not multirotor_available(), reason="multirotor is not installed")
def test_flights_agree_with_quadsims_model():
    """A nominal flight (2.1 s logged) and a +0.5 kg flight (0.5 s), one process: 500 Hz,
    scalar-first unit quaternions near level, commands in 0..1; the logged rotor speeds in
    quadsim's rotor model (b, d, arms, spins converted from multirotor) with the shared body
    drag reproduce the logged specific force and body accelerations: the mean thrust is the
    accelerometer's body z force (1 %) and about the weight (3 %: the path climbs and
    tilts; each flight with its own mass), and on the nominal flight quadsim's residual
    wrench stays below 1.5 % of the weight (forces) and 1.5 % of weight x arm (torques)
    RMS; the mean speed per command follows the steady map (3 %)."""
    from benchmarks.multirotor_cases import shared_effects
    from benchmarks.multirotor_source import multirotor_flights
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    params = vehicle_params()
    base = FlightSpec(seed=5, speed=0.8, duration=2.1)
    heavy = FlightSpec(seed=6, speed=0.8, duration=0.5, effects={"mass": 0.5})
    (log, truth), (log_heavy, _) = multirotor_flights([base, heavy], workers=1)
    assert truth["effects"] == {} and truth["source"] == "multirotor"
    assert log.t[1] == pytest.approx(1.0 / 500)
    assert np.all(log.quat[:, 0] > 0.9)
    np.testing.assert_allclose(np.linalg.norm(log.quat, axis=1), 1.0, atol=1e-9)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))
    weight = params.mass * 9.81
    for flight, mass in ((log, params.mass), (log_heavy, params.mass + 0.5)):
        thrust = params.thrust_factor * np.sum(flight.rotor_speed ** 2, axis=1)
        assert np.mean(flight.accel[:, 2]) * mass == pytest.approx(np.mean(thrust), rel=0.01)
        assert np.mean(thrust) == pytest.approx(mass * 9.81, rel=0.03)
    ratio = np.mean(log.rotor_speed) / np.mean(steady_speed(log.rotor_command))
    assert ratio == pytest.approx(1.0, rel=0.03)
    flight = prepare([log], params)[0]
    r = residuals(flight.fit, params, shared_effects(), rotor_channel=False)
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    assert np.all(rms[:3] < 0.015 * weight), rms
    assert np.all(rms[3:6] < 0.015 * weight * MODEL["arm"]), rms
