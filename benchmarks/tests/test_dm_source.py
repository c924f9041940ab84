"""The drone-models flight source (benchmarks.dm_source, dm_worker, dm_cases): the cf21B_500
parameter set against closed forms of its params.toml, the frozen case list, and -- with
drone-models installed (``pip install -e '.[dm]'``: drone-models 0.1.0 with numpy>=2,
scipy>=1.17, casadi, array-api-compat/extra) -- drone-models' own derivative at hover, in free fall
and under random rotor speeds, this project's RK4 against the free fall's closed form, and
two short flights checked against quadsim's model. drone-models is evaluated in a child
interpreter (it needs SciPy's array-API mode, which this process must not switch on)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.dm_source import RPM, FlightSpec, dm_available

needs_dm = pytest.mark.skipif(not dm_available(), reason="drone-models is not installed")

#: cf21B_500 in drone-models 0.1.0's data/params.toml
MASS, G, L = 0.04338, 9.81, 0.035355
C1, C2 = -3.133427287299859e-7, 4.407354891648379e-10          # N/RPM, N/RPM^2
DRAG = np.diag([-0.02149163, -0.02149163, -0.02359736])          # N/(m/s), body


def _state(n: int, rpm: float = 0.0) -> np.ndarray:
    x = np.zeros((n, 17))
    x[:, 6] = 1.0                                                # xyzw identity
    x[:, 13:17] = rpm
    return x


@needs_dm
def test_hover_and_max_rpm_closed_form():
    """Hover: 4 (c1 W + c2 W^2) = m g, W = (-c1 + sqrt(c1^2 + c2 m g)) / (2 c2) = 15896.30
    RPM (1664.67 rad/s); the RPM at thrust_max 0.2 N: 21660.72; the parameter set's b and d
    are the curves' quadratic coefficients per (rad/s)^2, its rotor positions (+-L, +-L) and
    its layout the mixing matrix's (1e-12)."""
    from benchmarks.dm_source import hover_rpm, max_rpm, vehicle_params

    hover = (-C1 + np.sqrt(C1 ** 2 + C2 * MASS * G)) / (2 * C2)
    assert hover == pytest.approx(15896.30, abs=0.01)
    assert hover_rpm() == pytest.approx(hover, rel=1e-12)
    assert 4 * (C1 * hover + C2 * hover ** 2) == pytest.approx(MASS * G, rel=1e-12)
    assert max_rpm() == pytest.approx((-C1 + np.sqrt(C1 ** 2 + 4 * C2 * 0.2)) / (2 * C2),
                                      rel=1e-12)
    assert max_rpm() == pytest.approx(21660.72, abs=0.01)
    params = vehicle_params()
    assert params.thrust_factor == pytest.approx(C2 / RPM ** 2, rel=1e-12)
    assert params.drag_factor == pytest.approx(2.4693477924534137e-12 / RPM ** 2, rel=1e-12)
    assert params.mass == MASS and params.gravity == G
    np.testing.assert_allclose(params.rotor_positions[:, :2],
                               L * np.array([[1, -1], [-1, -1], [-1, 1], [1, 1]]), rtol=1e-12)
    np.testing.assert_allclose(params.rotor_spins, [1, -1, 1, -1])


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases, the same on a second draw: 6 no-effect, 20 in-library, 2
    outside; seeds apart from the references'; each in-library truth (not a delay) is a
    library effect named by its true difference on top of the three shared effects (the
    motor and drag cases: the shared effects scaled); the draws within the module table."""
    if not dm_available():
        pytest.skip("drone-models is not installed")
    from benchmarks import dm_cases
    from quadsim.effects import EFFECTS

    cases = dm_cases.case_list()
    assert dm_cases.case_list() == cases and len(cases) == 28
    kinds = [c["kind"] for c in cases]
    assert (kinds.count("none"), kinds.count("library"), kinds.count("outside")) == (6, 20, 2)
    assert not {c["seed"] for c in cases} & {s.seed for s in dm_cases.reference_specs()}
    arm = L * np.sqrt(2.0)
    for case in cases:
        e = case["effects"]
        if case["kind"] == "library" and case["truth"] != "rotor_delay":
            names = [x.name for x in dm_cases.library_truth(case)]
            assert tuple(names[:3]) == ("motor_lag", "rotor_drag", "thrust_curve"), names
            assert case["truth"] in EFFECTS
            assert case["truth"] in names[3:] or (case["truth"] in ("motor_lag", "rotor_drag")
                                                  and len(names) == 3)
        if "mass" in e:
            assert 0.05 <= e["mass"] / MASS <= 0.2
        if "payload" in e:
            assert 0.004 <= e["payload"][0] <= 0.008
        if "com" in e:
            assert 0.03 <= np.hypot(*e["com"]) / arm <= 0.1
        if "motor_slow" in e:
            assert 1.5 <= e["motor_slow"] <= 2.5
        if "drag_scale" in e:
            assert 1.5 <= e["drag_scale"] <= 2.5
        if "wind" in e:
            assert 1.0 <= np.hypot(*e["wind"]) <= 2.5
    lag, drag, curve = dm_cases.shared_effects()
    hover = (-C1 + np.sqrt(C1 ** 2 + C2 * MASS * G)) / (2 * C2)
    # 1 / (c1 + 2 c2 W) at hover, up: 13.996 + 2 x 1.1093e-4 x 15896.3
    assert lag.time_constant == pytest.approx(1 / (13.996001897562685
                                                   + 2 * 0.00011093207920685363 * hover))
    assert drag.coefficient == pytest.approx(0.02149163 / (4 * hover * RPM), rel=1e-9)
    assert curve.linear == pytest.approx(C1 / RPM, rel=1e-12)


def _run(code: str) -> str:
    """``code`` in a child interpreter with drone-models importable (benchmarks/ on its path);
    its stdout."""
    bench = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "SCIPY_ARRAY_API": "1"}
    done = subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {bench!r})\n"
                           + code], env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr[-500:]
    return done.stdout


@needs_dm
def test_drone_models_derivative_at_hover_in_free_fall_and_per_rotor():
    """drone-models' own derivative (``dm_source.probe``): at the hover RPM, level and still,
    no acceleration (1e-9 m/s^2, 1e-9 rad/s^2); with no command and the rotors stopped,
    gravity plus the drag matrix on the velocity, D v / m (1e-12); at random rotor speeds
    (rotor = command, no rate), J w' is quadsim's rotor torques from the parameter set's
    layout and spins plus the curves' linear terms on the same layout (1e-9 relative)."""
    from benchmarks.dm_source import hover_rpm, probe, vehicle_params
    from quadsim.vehicle.rotors import rotor_wrench

    hover = hover_rpm()
    d = probe(_state(1, hover), np.full((1, 4), hover))
    np.testing.assert_allclose(d[0, 7:13], 0.0, atol=1e-9)
    x = _state(1)
    x[0, 7:10] = (1.0, -0.5, -2.0)
    d = probe(x, np.zeros((1, 4)))
    np.testing.assert_allclose(d[0, 7:10], [0, 0, -G] + DRAG @ x[0, 7:10] / MASS, atol=1e-12)
    params = vehicle_params()
    rng = np.random.default_rng(3)
    rpm = rng.uniform(9000.0, 21000.0, (5, 4))
    x = _state(5)
    x[:, 13:17] = rpm
    d = probe(x, rpm)
    J = np.diag([25e-6, 28e-6, 49e-6])
    for k in range(5):
        force, torque = rotor_wrench(params, rpm[k] * RPM)
        linear = C1 * rpm[k]                                      # N per rotor
        linear_torque = 1.65886356219615e-9 * rpm[k]              # N m per rotor
        extra = (np.cross(params.rotor_positions, np.outer(linear, [0, 0, 1])).sum(axis=0)
                 + np.array([0, 0, -np.sum(params.rotor_spins * linear_torque)]))
        np.testing.assert_allclose(J @ d[k, 10:13], torque + extra, rtol=1e-9, atol=1e-15)
        assert MASS * (d[k, 9] + G) == pytest.approx(force[2] + linear.sum(), rel=1e-9)


@needs_dm
def test_rk4_free_fall_against_the_closed_form():
    """No command, rotors stopped, level and at rest: this project's RK4 at 500 Hz on
    drone-models' derivative for 1 s gives v(t) = -(g/a)(1 - e^(-a t)) and z(t) = z0 - (g/a) t
    + (g/a^2)(1 - e^(-a t)), a = -D_zz / m = 0.544 /s (1e-10 m/s, 1e-10 m); the attitude
    stays level."""
    out = _run("""
import numpy as np
import dm_worker
from drone_models.core import parametrize
from drone_models.first_principles import dynamics
f = parametrize(dynamics, "cf21B_500")
def deriv(x, cmd, t):
    d = list(f(x[:, 0:3], x[:, 3:7], x[:, 7:10], x[:, 10:13], cmd, x[:, 13:17]))
    d[1] = dm_worker.quat_dot(x[:, 3:7], x[:, 10:13])
    return np.concatenate(d, axis=1)
x = np.zeros((1, 17)); x[0, 6] = 1.0; x[0, 2] = 10.0
for k in range(500):
    x = dm_worker.rk4_step(deriv, x, np.zeros((1, 4)), k / 500, 1 / 500)
print(repr(x[0].tolist()))
""")
    x = np.array(eval(out))
    a = 0.02359736 / MASS
    t = 1.0
    assert x[9] == pytest.approx(-(G / a) * (1 - np.exp(-a * t)), abs=1e-10)
    assert x[2] == pytest.approx(10.0 - G / a * t + G / a ** 2 * (1 - np.exp(-a * t)),
                                 abs=1e-10)
    np.testing.assert_allclose(x[3:7], [0, 0, 0, 1], atol=1e-15)


def test_quat_dot_is_the_body_rate_formula():
    """The worker's quaternion derivative (xyzw) is q (x) (0, w) / 2: at level, a body roll
    rate of 1 rad/s gives x' = 0.5; after a 90 deg yaw the same body roll rate still turns
    the body about its own x axis: R^T R(q + h q') is a rotation by h about x (h = 1e-6,
    to 1e-11)."""
    bench = str(Path(__file__).resolve().parents[1])
    code = (f"import sys; sys.path.insert(0, {bench!r}); import dm_worker, numpy as np; "
            "w = np.array([[1.0, 0, 0]]); h = 1e-6; "
            "q = np.array([[0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]]); "
            "p = q + h * dm_worker.quat_dot(q, w); p /= np.linalg.norm(p); "
            "m = dm_worker._rot(q)[0].T @ dm_worker._rot(p)[0]; "
            "print([dm_worker.quat_dot(np.array([[0.0, 0, 0, 1]]), w)[0].tolist(), "
            "m.tolist()])")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    level, m = eval(done.stdout)
    np.testing.assert_allclose(level, [0.5, 0, 0, 0])
    h = 1e-6
    np.testing.assert_allclose(m, [[1, 0, 0], [0, np.cos(h), -np.sin(h)],
                                   [0, np.sin(h), np.cos(h)]], atol=1e-11)


@needs_dm
def test_flights_agree_with_quadsims_model():
    """A nominal flight and a +4 g flight (2.1 s logged each, one child process): 500 Hz,
    w-first unit quaternions, commands in 0..1; the full thrust curve of the logged rotor
    speeds (b W^2 + c1 W) is the accelerometer's body-z force times the flight's mass (1 %);
    quadsim's residual wrench on the nominal flight with the three shared effects stays
    below 1.5 % of the weight (forces) and of weight x arm (torques) RMS."""
    from benchmarks.dm_cases import shared_effects
    from benchmarks.dm_source import dm_flights, vehicle_params
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    base = FlightSpec(seed=5, speed=0.9, duration=2.1)
    heavy = FlightSpec(seed=6, speed=0.9, duration=2.1, effects={"mass": 0.004})
    (log, truth), (log_heavy, _) = dm_flights([base, heavy])
    assert truth["effects"] == {} and truth["source"] == "drone-models"
    assert log.t[1] == pytest.approx(1.0 / 500)
    assert np.all(log.quat[:, 0] > 0.9)
    np.testing.assert_allclose(np.linalg.norm(log.quat, axis=1), 1.0, atol=1e-9)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))
    params = vehicle_params()
    for flight, mass in ((log, MASS), (log_heavy, MASS + 0.004)):
        w = flight.rotor_speed
        thrust = np.sum(params.thrust_factor * w ** 2 + C1 / RPM * w, axis=1)
        assert np.mean(flight.accel[:, 2]) * mass == pytest.approx(np.mean(thrust), rel=0.01)
    weight = MASS * G
    r = residuals(prepare([log], params)[0].fit, params, shared_effects(),
                  rotor_channel=False)
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    assert np.all(rms[:3] < 0.015 * weight), rms
    assert np.all(rms[3:6] < 0.015 * weight * L * np.sqrt(2.0)), rms
