"""``gap`` on logs with the IMU, the motors and the attitude but no position (the on-board
estimate's Euler angles or quaternion, as most flight controllers log them; issue 47, logs as
users have them): the attitude is kept, the accelerometer turned to the world by it gives the
vehicle's acceleration (``logcheck.posefree_states``), and the effects that read only the
attitude (a payload swinging on a cable) are weighed; those that read the speed or the height
(drag, wind, ground effect) are not, and the answer says so.

Generated closed-loop flights (quadsim.logs.generate, MuJoCo, sensor noise) with their
position and velocity columns dropped, the attitude kept; and, where ../shared is present,
the real mixed flights cut alike."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from quadsim.core.errors import QuadsimWarning
from quadsim.effects import EFFECTS, EffectSet, make_effect
from quadsim.effects.facts import without_pose
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import judge_one, prepare
from quadsim.gap.fitting import CableSwing
from quadsim.gap.logcheck import logged_parts, missing_words, needs_pose, posefree_states
from quadsim.gap.residual import flight_states
from quadsim.logs.checks import check_logs
from quadsim.logs.flightlog import WITHOUT_POSE, WITHOUT_POSITION, FlightLog, load_log
from quadsim.logs.generate import generate_flight
from quadsim.vehicle.params import load_params

from _helpers import assert_payload_named, judge_real_cut, posefree_noise

NOISE = posefree_noise()
PATHS = ("figure8", "steps", "lissajous", "figure8")
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazyflie21_brushless"

pytestmark = pytest.mark.xdist_group("test_gap_attitude")


def _attitude_only(log):
    return dataclasses.replace(log, position=None, velocity=None)


def test_the_loader_keeps_an_attitude_logged_without_a_position(tmp_path):
    """A CSV with t, the attitude as Euler angles, the IMU and the commands: the attitude is
    read (the quaternion of roll, pitch, yaw), no pose, and the stage's words say which."""
    n = 200
    t = np.arange(n) * 0.01
    roll = 0.2 * np.sin(t)
    rows = ["t,roll,pitch,yaw,wx,wy,wz,ax,ay,az,cmd_1,cmd_2,cmd_3,cmd_4"]
    rate = 0.2 * np.cos(t)                  # the gyro agrees with the attitude (roll rate)
    rows += [f"{t[k]:.3f},{roll[k]:.6f},0,0,{rate[k]:.6f},0,0,0,0,9.81,0.4,0.4,0.4,0.4"
             for k in range(n)]
    path = tmp_path / "att.csv"
    path.write_text("\n".join(rows) + "\n")
    log = load_log(path, warn=False)
    assert log.position is None and log.quat is not None and log.velocity is None
    assert not log.has_pose and log.has_attitude
    np.testing.assert_allclose(log.quat[:, 1], np.sin(roll / 2), atol=1e-6)
    assert log.without_pose_words == WITHOUT_POSITION
    bare = dataclasses.replace(log, quat=None)
    assert bare.without_pose_words == WITHOUT_POSE and not bare.has_attitude
    assert logged_parts(log) == {"attitude"} and logged_parts(bare) == set()
    # the checks say what they compared: the gyro against the attitude where it is logged
    from quadsim.logs.checks import check_log_stretches

    _, notes = check_log_stretches(log)
    assert any("the gyro is checked against the attitude, the accelerometer by its magnitude"
               in n for n in notes), notes
    _, notes = check_log_stretches(bare)
    assert any("the gyro and accelerometer are checked by their magnitudes" in n
               for n in notes), notes


def test_what_an_attitude_adds_to_the_effects_weighed():
    """The attitude alone adds no effect of the library: each that reads the pose reads the
    speed or the height too (the cable payload reads neither: it is weighed with the IMU
    alone, tests/test_imu_swing.py); the words name only what is still missing."""
    attitude = logged_parts(FlightLog(np.arange(3.0), None, np.tile([1.0, 0, 0, 0], (3, 1))))
    assert not needs_pose([("cable_payload", {}, ("mass",))], attitude)
    assert not needs_pose([("cable_payload", {}, ("mass",))])
    assert all(needs_pose([(name, {}, ())], attitude) for name in without_pose(EFFECTS))
    said = missing_words(attitude)
    assert said.startswith("no velocity or height logged: ") and "cable payload" not in said
    assert "with the logged attitude" in said and "qw..qz" not in said
    assert missing_words().startswith("no velocity, height or attitude logged: ")


def test_the_vehicle_acceleration_is_the_accelerometer_turned_to_the_world(cf_states):
    """posefree_states: a = R f - g e_z, the states' own smoothed specific force turned by
    their attitude (an independent rotation matrix); through the cable's 0.25 s filter
    (fitting._derivative) it is the generated flight's differentiated velocity to the
    sensors' noise (measured: 0.05 of 0.48 m/s^2 RMS), with no bias."""
    from quadsim.gap.fitting import _derivative

    posed, attitude = cf_states
    r = np.array([quat_matrix(q) for q in attitude.quat])
    want = np.einsum("bij,bj->bi", r, attitude.specific_force) - [0.0, 0.0, 9.81]
    np.testing.assert_allclose(attitude.accel_world, want, atol=1e-12)
    assert not attitude.pose and attitude.attitude
    inner = slice(50, -50)
    from_v = _derivative(posed.t, posed.velocity)[inner]
    err = _derivative(attitude.t, attitude.accel_world, deriv=0)[inner] - from_v
    assert np.sqrt(np.mean(err ** 2)) < 0.2 * np.sqrt(np.mean(from_v ** 2))
    assert np.all(np.abs(err.mean(axis=0)) < 0.01)


def test_a_cable_pulls_alike_from_the_velocity_and_from_the_acceleration(cf, cf_states):
    """The swing integrated from the differentiated velocity (a pose) and from the
    acceleration the accelerometer gives (no position): the same pull to the noise."""
    posed, attitude = cf_states
    cable = CableSwing(mass=0.005, length=0.4)
    from_v, _, swing_v = cable.pull(posed.t, posed.position, posed.velocity, posed.quat,
                                    posed.body_rate, cf)
    from_a, _, swing_a = cable.pull(attitude.t, attitude.position, attitude.velocity,
                                    attitude.quat, attitude.body_rate, cf,
                                    accel_world=attitude.accel_world)
    assert np.allclose(attitude.velocity, 0.0)       # the stand-in: nothing read from it
    inner = slice(50, -50)
    scale = np.sqrt(np.mean(from_v[inner] ** 2))
    assert np.sqrt(np.mean((from_a - from_v)[inner] ** 2)) < 0.1 * scale
    assert np.max(np.abs(swing_a - swing_v)[inner]) < 0.05      # rad


def quat_matrix(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def cf_states(cf):
    """A generated figure-8's states with its pose, and the same log without a position."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        log, _ = generate_flight(cf, "figure8", EffectSet(()), NOISE, 5, duration=5.0,
                                 speed=1.0)
    from quadsim.gap.logcheck import posefree_log

    posed = flight_states(log)
    bare = _attitude_only(log)
    attitude = posefree_states(flight_states(posefree_log(bare)), True, cf.gravity)
    return posed, attitude


def _fly(cf, effects, seed, path="figure8", keep=_attitude_only):
    log, _ = generate_flight(cf, path, EffectSet(tuple(effects)), NOISE, seed, duration=5.0,
                             speed=1.0)
    return check_logs([keep(log)], cf)[0][0]


def _imu_only(log):
    return dataclasses.replace(log, position=None, velocity=None, quat=None)


@pytest.mark.parametrize("keep", [_attitude_only, _imu_only], ids=["attitude", "imu"])
def test_a_cable_payload_is_named_with_or_without_the_attitude(cf, keep):
    """4 nominal references and two flights, all without a position (with the attitude, or
    the IMU and motors alone: the swing in the gyro's own frame, tests/test_imu_swing.py): a
    nominal one is clear, one with 6 g on a 0.5 m cable is read as a payload on a cable
    (alone or with a part fixed to the frame) within 1.5 g of its mass; the answer's "Not
    weighed" names only the speed and height (and the attitude where it is not logged), never
    the cable, nor does the posterior weigh a drag."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [_fly(cf, (), seed, path, keep) for seed, path in enumerate(PATHS)]
        reference = calibrate(prepare(refs, cf), cf)
        calm = judge_one(_fly(cf, (), 11, keep=keep), reference)
        slung = judge_one(_fly(cf, (make_effect("cable_payload", mass=0.006, length=0.5),),
                               12, keep=keep), reference)
    assert calm.outcome == "no_significant_gap", calm.answer
    assert slung.name.startswith("cable_payload"), slung.answer
    total = sum(v for k, v in slung.params.items() if k.endswith(".mass"))
    assert abs(total - 0.006) < 0.0015, slung.params
    said = missing_words({"attitude"} if keep is _attitude_only else ())
    assert "cable payload" not in said
    for verdict in (calm, slung):
        assert f"Not weighed: {said}" in verdict.answer
    assert not {r.name for r in slung.posterior} & {"wind", "body_drag", "rotor_drag"}


@pytest.mark.skipif(not (DATA / "mixed_labels.json").is_file(), reason="../shared absent")
def test_real_payload_flights_with_their_attitude_and_no_position(tmp_path):
    """Two real mixed payload flights (+7.4 g, 4.7 g of it on a cable) and a plain one, cut
    to the IMU, the commands and the attitude (no position, velocity or rotor speeds),
    against five nominal flights cut alike, as a user types it: the payloads named on a cable
    within 2 g of +7.4 g in all, the plain flight clear."""
    def keep(log):
        return dataclasses.replace(log, position=None, velocity=None, rotor_speed=None)

    by = judge_real_cut(tmp_path, keep, (0, 4, 8, 12, 16), (106, 112, 114))
    assert_payload_named(by["flight_106.csv.gz"])
    assert_payload_named(by["flight_112.csv.gz"])
    assert by["flight_114.csv.gz"]["verdict"] == "no_significant_gap", by["flight_114.csv.gz"]


def test_euler_angles_in_degrees_are_refused_in_one_line(tmp_path, capsys):
    """roll, pitch, yaw are rad (z-y-x): a pitch column beyond pi/2 (+ PITCH_SLACK) cannot be
    one, and a log written in degrees has one once it pitches by more than 1.6 degrees: refused
    naming the file and the column, exit 2 through the CLI, nothing written; a pitch of
    exactly pi/2 (the gimbal point) is read."""
    from quadsim.core.errors import InputError
    from quadsim.gap.__main__ import main
    from quadsim.logs.flightlog import PITCH_SLACK

    n = 300
    t = np.arange(n) * 0.01

    def write(name, pitch):
        rows = ["t,roll,pitch,yaw,wx,wy,wz,ax,ay,az,cmd_1,cmd_2,cmd_3,cmd_4"]
        rows += [f"{t[k]:.3f},0,{pitch[k]:.6f},0,0,0,0,0,0,9.81,0.4,0.4,0.4,0.4"
                 for k in range(n)]
        path = tmp_path / name
        path.write_text("\n".join(rows) + "\n")
        return path

    degrees = write("deg.csv", 5.0 * np.sin(t))
    with pytest.raises(InputError, match=r"deg\.csv: pitch: \|pitch\| up to 5, beyond pi/2"):
        load_log(degrees)
    out = tmp_path / "out.json"
    other = write("deg2.csv", 5.0 * np.cos(t))
    assert main(["--model", "crazyflie21", "--per-flight", str(degrees), "--reference",
                 str(other), "--workers", "1", "--no-cache", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"error: {degrees}: pitch: ") and not out.exists()
    edge = write("edge.csv", np.full(n, np.pi / 2))
    assert load_log(edge, warn=False).has_attitude
    assert np.pi / 2 + PITCH_SLACK < 1.6      # a degree log pitching by 1.6 degrees is caught
