"""The Crazyflow flight source (benchmarks.crazyflow_source): frames, units and determinism
against closed forms and against Crazyflow's own dynamics function. Skipped with the reason
when crazyflow is not installed (``pip install -e '.[crazyflow]'``). Crazyflow runs in a
child process (it needs SciPy's array-API mode), so nothing here imports it."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from benchmarks.crazyflow_source import (
    RPM,
    FlightSpec,
    _flight_job,
    crazyflow_available,
    crazyflow_flights,
    crazyflow_params,
    hover_rpm,
    vehicle_params,
)
from benchmarks.score import score_case
from quadsim.logs.flightlog import log_bytes
from quadsim.vehicle.rotors import rotor_wrench

needs_crazyflow = pytest.mark.skipif(not crazyflow_available(),
                                     reason="crazyflow not installed "
                                            "(pip install -e '.[crazyflow]')")

_CRAZYFLOW_WRENCH = r"""
import json, sys
import crazyflow  # noqa: F401 (array-API flag before SciPy)
import numpy as np
from crazyflow.dynamics import parametrize
from crazyflow.dynamics.first_principles import dynamics
fn = parametrize(dynamics, "cf21B_500")
out = []
for rpm in json.loads(sys.stdin.read()):
    rpm = np.asarray(rpm, dtype=float)
    _, _, acc, ang_acc, _ = fn(pos=np.zeros(3), quat=np.array([0.0, 0.0, 0.0, 1.0]),
                               vel=np.zeros(3), ang_vel=np.zeros(3), cmd=rpm, rotor_vel=rpm)
    out.append([np.asarray(acc).tolist(), np.asarray(ang_acc).tolist()])
print(json.dumps(out))
"""


def _crazyflow_accelerations(rpms: list) -> list:
    """Crazyflow's own dynamics function at rest (level, zero rates) for rotor speeds (RPM):
    [(linear acceleration m/s^2 world, angular acceleration rad/s^2 body)]."""
    env = {**os.environ, "SCIPY_ARRAY_API": "1", "JAX_PLATFORMS": "cpu"}
    done = subprocess.run([sys.executable, "-c", _CRAZYFLOW_WRENCH], input=json.dumps(rpms),
                          env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


@needs_crazyflow
def test_vehicle_params_match_crazyflow_curves_and_layout():
    """b Omega_h^2 equals Crazyflow's thrust curve at hover within 1 % (a least-squares fit
    over 0.75-1.25 x hover of a curve with a small linear term), 4 b Omega_h^2 = m g; rotors
    at (+-L, +-L) from the mixing matrix, motor 1 front-right."""
    params, cp = vehicle_params(), crazyflow_params()
    hover = hover_rpm(cp)
    curve = np.polyval(np.ravel(cp["rpm2thrust"])[::-1], hover)
    assert 4 * curve == pytest.approx(params.weight, rel=1e-9)
    assert params.thrust_factor * (hover * RPM) ** 2 == pytest.approx(curve, rel=0.01)
    arm = float(np.ravel(cp["L"])[0])
    np.testing.assert_allclose(params.rotor_positions[0], [arm, -arm, 0.0], rtol=1e-12)
    np.testing.assert_allclose(np.abs(params.rotor_positions[:, :2]), arm, rtol=1e-12)


@needs_crazyflow
def test_wrench_and_yaw_sign_agree_with_crazyflow_dynamics():
    """At rest, Crazyflow's own dynamics function and quadsim's rotor model of the converted
    parameters give the same accelerations: hover speeds -> zero net acceleration (thrust =
    weight, 1e-9); the ccw-reaction pair faster -> a pure yaw acceleration of the same sign
    and size (d is a fit of a curve: 3 %); one side faster -> roll/pitch of the same sign and
    size (b fit: 3 %)."""
    params, cp = vehicle_params(), crazyflow_params()
    hover = hover_rpm(cp)
    inv = np.linalg.inv(params.inertia)
    yaw = hover * np.array([0.95, 1.05, 0.95, 1.05])      # rotors 2, 4: M[2, i] = +1
    left = hover * np.array([0.97, 0.97, 1.03, 1.03])     # rotors 3, 4 at y = +L
    front = hover * np.array([1.03, 0.97, 0.97, 1.03])    # rotors 1, 4 at x = +L
    results = _crazyflow_accelerations([[hover] * 4, yaw.tolist(), left.tolist(),
                                        front.tolist()])
    np.testing.assert_allclose(results[0][0], 0.0, atol=1e-9)
    np.testing.assert_allclose(results[0][1], 0.0, atol=1e-9)
    for rpm, (_, ang_acc) in zip((yaw, left, front), results[1:]):
        _, torque = rotor_wrench(params, rpm * RPM)
        ours = inv @ torque
        big = np.argmax(np.abs(ours))
        assert np.sign(ang_acc[big]) == np.sign(ours[big])
        assert ang_acc[big] == pytest.approx(ours[big], rel=0.03)
        others = np.delete(np.arange(3), big)
        np.testing.assert_allclose(np.asarray(ang_acc)[others], 0.0, atol=1e-6 * abs(ours[big]))
    # signs in words: faster ccw-reaction pair yaws left (+z); left side up rolls +x; front
    # up pitches nose up, which is -y about body y (x forward, y left, z up)
    assert results[1][1][2] > 0 and results[2][1][0] > 0 and results[3][1][1] < 0


@needs_crazyflow
def test_com_offset_moves_the_lever_arms():
    """A CoM moved by c changes Crazyflow's mixing matrix so that its roll/pitch torque is
    sum (r_i - c) x f_i e_z exactly (closed form, 1e-12)."""
    cp = crazyflow_params()
    c = np.array([0.002, -0.003])
    job = _flight_job(FlightSpec(seed=0, effects={"com": tuple(c)}), cp)
    f = np.array([0.09, 0.11, 0.10, 0.12])
    arm = float(np.ravel(cp["L"])[0])
    torque = (job["mixing_matrix"] @ (f * arm))[:2]
    r = vehicle_params().rotor_positions[:, :2] - c
    np.testing.assert_allclose(torque, [np.sum(r[:, 1] * f), -np.sum(r[:, 0] * f)], rtol=1e-12)


@needs_crazyflow
def test_flights_hover_thrust_units_and_same_bytes():
    """Two flights in one Crazyflow process, the first again in another process: the same
    spec gives the same log bytes; on the nominal near-hover flight Crazyflow's own thrust
    curve at the logged speeds (rad/s -> RPM) carries the weight (median within 1 %), the
    accelerometer reads +g on body z (0.1 m/s^2, z up) and the attitude is near level
    (scalar-first quaternion); +5 g: the curve carries the heavier vehicle (1 %)."""
    cp = crazyflow_params()
    base = FlightSpec(seed=3, speed=0.05, duration=2.0)
    heavy = FlightSpec(seed=4, speed=0.05, duration=2.0, effects={"mass": 0.005})
    (log, truth), (log_heavy, _) = crazyflow_flights([base, heavy])
    (again, _), = crazyflow_flights([base])
    assert log_bytes(log, gzipped=True) == log_bytes(again, gzipped=True)
    assert truth["effects"] == {} and truth["source"] == "crazyflow"
    curve = np.ravel(cp["rpm2thrust"])[::-1]
    for flight, mass in ((log, float(cp["mass"])), (log_heavy, float(cp["mass"]) + 0.005)):
        thrust = np.sum(np.polyval(curve, flight.rotor_speed / RPM), axis=1)
        assert np.median(thrust) == pytest.approx(mass * 9.81, rel=0.01)
    assert np.median(log.accel[:, 2]) == pytest.approx(9.81, abs=0.1)
    assert np.all(log.quat[:, 0] > 0.99)
    assert np.all((log.rotor_command > 0) & (log.rotor_command < 1))


def test_delay_truth_is_named_by_any_delay_reading():
    """The scorer: a rotor-log delay is named by a reading whose name contains 'delay', and
    only by such a reading."""
    verdict = {"outcome": "named", "lead": ["signal_delay"], "named": ["signal_delay"],
               "readings": 1, "alternatives": [], "confident": True}
    assert score_case("rotor_delay", "library", verdict)["named"]
    other = {**verdict, "lead": ["motor_lag"], "named": ["motor_lag"]}
    score = score_case("rotor_delay", "library", other)
    assert not score["named"] and score["confident_wrong"]


def test_refused_flight_scores_as_neither_named_nor_no_gap():
    """A flight the diagnosis refuses (issue 22, batches go on) is read as ``refused``: it
    names nothing, is not a no_significant_gap and not a confident name."""
    from benchmarks.score import read_verdict

    verdict = read_verdict({"outcome": "refused", "reason": "accelerometer check failed"})
    assert verdict["outcome"] == "refused" and verdict["named"] == []
    score = score_case("none", "none", verdict)
    assert not score["no_gap"] and not score["confident_wrong"]
