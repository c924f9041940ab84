"""The PyFlyt flight source (benchmarks.pyflyt_source): frames, units, spins and determinism
against PyFlyt's own dynamics (pybullet's step with PyFlyt's motors and forces). Skipped when
PyFlyt is not installed (``pip install pybullet pettingzoo`` then ``pip install --no-deps
PyFlyt==0.29.0``). pybullet prints from C, so PyFlyt runs in child processes only."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("PyFlyt")

from benchmarks.pyflyt_source import (
    PHYSICS_HZ,
    RPM,
    WORKER_ENV,
    FlightSpec,
    hover_throttle,
    motor_response,
    pyflyt_flights,
    pyflyt_model,
    vehicle_params,
)
from quadsim.core.frames import euler_to_quat, quat_to_rotmat
from quadsim.logs.flightlog import log_bytes
from quadsim.vehicle.rotors import rotor_wrench

# One pybullet step of PyFlyt's QuadX (noise_ratio 0 in a copy of its cf2x.yaml) from rest at
# a given attitude with the motors held at given throttles: PyFlyt's own motor forces and
# torques (and its drag terms, zero at rest); returns world-frame linear and angular
# accelerations (m/s^2, rad/s^2) from pybullet's velocity step.
_PYFLYT_STEP = r"""
import json, os, shutil, sys, tempfile, warnings
warnings.simplefilter("ignore")
import numpy as np, yaml, PyFlyt
from PyFlyt.core import Aviary
cases = json.loads(sys.stdin.read())
tmp = tempfile.mkdtemp()
src = os.path.join(os.path.dirname(PyFlyt.__file__), "models", "vehicles", "cf2x")
dst = os.path.join(tmp, "cf2x")
shutil.copytree(src, dst)
cfg = yaml.safe_load(open(os.path.join(dst, "cf2x.yaml")))
cfg["motor_params"]["noise_ratio"] = 0.0
yaml.safe_dump(cfg, open(os.path.join(dst, "cf2x.yaml"), "w"))
env = Aviary(start_pos=np.array([[0.0, 0.0, 2.0]]), start_orn=np.zeros((1, 3)), render=False,
             drone_type="quadx", physics_hz=240, seed=1,
             drone_options={"model_dir": tmp, "drone_model": "cf2x", "control_hz": 120})
drone = env.drones[0]
out = []
for throttle, euler in cases:
    env.resetBasePositionAndOrientation(drone.Id, [0.0, 0.0, 2.0],
                                        env.getQuaternionFromEuler(euler))
    env.resetBaseVelocity(drone.Id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    drone.update_state()
    quat = list(env.getBasePositionAndOrientation(drone.Id)[1])
    drone.motors.throttle = np.array(throttle, dtype=float)
    drone.pwm = np.array(throttle, dtype=float)
    drone.update_physics()
    env.stepSimulation()
    lin, ang = env.getBaseVelocity(drone.Id)
    out.append([(np.array(lin) * 240).tolist(), (np.array(ang) * 240).tolist(), quat])
print("RESULT " + json.dumps(out))
"""


def _pyflyt_step(cases: list) -> list:
    done = subprocess.run([sys.executable, "-c", _PYFLYT_STEP], input=json.dumps(cases),
                          env={**os.environ, **WORKER_ENV}, capture_output=True, text=True,
                          check=True)
    line = [x for x in done.stdout.splitlines() if x.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def test_hover_and_differentials_agree_with_pyflyt():
    """PyFlyt's own step and quadsim's rotor model of the converted parameters give the same
    accelerations: the computed hover speed -> zero net acceleration (1e-9 of g); a yaw,
    roll and pitch differential -> angular accelerations of the same sign and size (1e-6,
    the same b, d and arms), level and rolled 0.3 rad / yawed 0.5 rad (world frame: the
    thrust and the yaw torque turn with the body, quaternion xyzw <-> wxyz)."""
    params, model = vehicle_params(), pyflyt_model()
    hover = hover_throttle(model)
    yaw = hover * np.array([1.05, 1.05, 0.95, 0.95])      # spin +1 pair faster: yaw -z
    roll = hover * np.array([0.97, 1.03, 1.03, 0.97])     # left rotors (2, 3) faster: +x
    pitch = hover * np.array([1.03, 0.97, 1.03, 0.97])    # front rotors (1, 3) faster: -y
    tilted = [0.3, -0.1, 0.5]
    cases = [(hover * np.ones(4), [0.0, 0.0, 0.0]), (yaw, [0.0] * 3), (roll, [0.0] * 3),
             (pitch, [0.0] * 3), (hover * np.ones(4), tilted), (yaw, tilted), (roll, tilted)]
    results = _pyflyt_step([(t.tolist(), e) for t, e in cases])
    np.testing.assert_allclose(results[0][0], 0.0, atol=1e-9 * 9.81)
    np.testing.assert_allclose(results[0][1], 0.0, atol=1e-9)
    inv = np.linalg.inv(params.inertia)
    for (throttle, euler), (acc, ang_acc, quat_xyzw) in zip(cases, results):
        quat = euler_to_quat(np.array([euler]))[0]
        np.testing.assert_allclose(np.array(quat_xyzw)[[3, 0, 1, 2]] * np.sign(quat_xyzw[3]),
                                   quat * np.sign(quat[0]), atol=1e-6)
        rot = quat_to_rotmat(quat[None])[0]
        force, torque = rotor_wrench(params, throttle * model["max_rpm"] * RPM)
        expected_acc = rot @ force / params.mass + np.array([0.0, 0.0, -9.81])
        np.testing.assert_allclose(acc, expected_acc, atol=1e-6 * 9.81)
        expected_alpha = rot @ (inv @ torque)
        np.testing.assert_allclose(ang_acc, expected_alpha,
                                   atol=1e-6 * max(1.0, np.abs(expected_alpha).max()))
    level = [np.asarray(r[1]) for r in results[1:4]]
    assert level[0][2] < 0 and level[1][0] > 0 and level[2][1] < 0   # signs in words
    for a in level:
        assert np.abs(a).max() > 10.0                                 # a real differential


def test_motor_response_closed_form():
    """PyFlyt's motor per step y' = (1 - a + 0.02 n) y + a u, n ~ N(4, 1): at 240 Hz and tau
    10 ms the mean steady gain is a / (a - 0.08) and the pole 1 - a + 0.08 (closed form,
    against a direct iteration of the mean recursion); 2.5 x tau at 500 Hz is refused."""
    gain, tau = motor_response(0.01, 0.02, 240)
    a = (1 / 240) / 0.01
    y = 0.0
    for _ in range(2000):
        y = (1 - a + 0.08) * y + a * 0.3
    assert y / 0.3 == pytest.approx(gain, rel=1e-12)
    assert np.exp(-(1 / 240) / tau) == pytest.approx(1 - a + 0.08, rel=1e-12)
    with pytest.raises(Exception, match="unstable"):
        motor_response(0.025, 0.02, 500)


def test_flights_hover_units_and_same_bytes():
    """A slow nominal flight and a +3 g flight in one PyFlyt process, the first again in
    another: the same spec gives the same log bytes; PyFlyt's thrust at the logged rotor
    speeds (rad/s -> its rpm) carries the weight (mean of the accelerometer's body z, 1 %:
    the log's specific force is pybullet's own velocity step) and the mean throttle/pwm
    ratio is the motor's steady gain (3 %); 240 Hz; attitude near level, scalar-first."""
    model, params = pyflyt_model(), vehicle_params()
    base = FlightSpec(seed=3, speed=0.05, duration=2.0)
    heavy = FlightSpec(seed=4, speed=0.05, duration=2.0, effects={"mass": 0.003})
    (log, truth), (log_heavy, _) = pyflyt_flights([base, heavy])
    (again, _), = pyflyt_flights([base])
    assert log_bytes(log, gzipped=True) == log_bytes(again, gzipped=True)
    assert truth["effects"] == {} and truth["source"] == "pyflyt"
    assert log.t[1] == pytest.approx(1.0 / PHYSICS_HZ)
    for flight, mass in ((log, model["mass"]), (log_heavy, model["mass"] + 0.003)):
        rpm = flight.rotor_speed / RPM
        thrust = model["thrust_coef"] * np.sum(rpm ** 2, axis=1)
        assert np.mean(thrust) == pytest.approx(mass * 9.81, rel=0.01)
        assert np.mean(flight.accel[:, 2]) * mass == pytest.approx(np.mean(thrust), rel=0.01)
    gain, _ = motor_response(model["tau"], model["noise_ratio"])
    ratio = np.mean(log.rotor_speed) / (np.mean(log.rotor_command) * params.max_speed)
    assert ratio == pytest.approx(gain, rel=0.03)
    assert np.all(log.quat[:, 0] > 0.99)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases: 6 no-effect, 18 in-library, 4 outside; seeds apart from the
    references'; every in-library truth is a library name (or a delay) and its true
    difference (on top of the shared physics: motor lag, body drag, rate damping) names it;
    the PyFlyt-side change is within the module table's ranges (mass +5..+20 %, tau x
    1.5-2.5 -> effective 19-46 ms, a stable motor)."""
    from benchmarks.pyflyt_cases import case_list, library_truth, reference_specs
    from quadsim.effects import EFFECTS

    cases, model = case_list(), pyflyt_model()
    assert case_list() == cases and len(cases) == 28
    kinds = [c["kind"] for c in cases]
    assert (kinds.count("none"), kinds.count("library"), kinds.count("outside")) == (6, 18, 4)
    assert not {c["seed"] for c in cases} & {s.seed for s in reference_specs()}
    damping = np.array([1e-5, 1e-5, 2e-5])
    for case in cases:
        if case["kind"] != "library" or case["truth"] == "rotor_delay":
            continue
        names = [e.name for e in library_truth(case, damping)]
        assert names[:3] == ["motor_lag", "body_drag", "rate_damping"]
        assert case["truth"] in EFFECTS and (case["truth"] in names or len(names) == 3)
        if "mass" in case["effects"]:
            assert 0.05 <= case["effects"]["mass"] / model["mass"] <= 0.2
        if "motor_slow" in case["effects"]:
            tau = motor_response(model["tau"] * case["effects"]["motor_slow"],
                                 model["noise_ratio"])[1]
            assert 0.018 < tau < 0.047
