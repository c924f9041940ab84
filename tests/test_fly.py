"""Flight generator, sensor models, reference paths and the tracking controller."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.core.frames import euler_to_quat, quat_conjugate, quat_multiply, rotate_inverse
from quadsim.effects import EffectSet, effect_set_from_specs
from quadsim.fly import main
from quadsim.logs.flightlog import FlightLog, load_log
from quadsim.logs.generate import generate_flight, truth_path
from quadsim.logs.sensors import SensorModel, parse_signal_values
from quadsim.sim.paths import PATHS, make_reference
from quadsim.vehicle.params import load_params

PARAMS = load_params("physical")


@pytest.mark.parametrize("name", PATHS)
def test_reference_derivatives_match_finite_differences(name):
    ref = make_reference(name, speed=1.5, height=1.0, size=0.8, duration=10.0)
    t = np.linspace(0.0, 10.0, 20001)
    s = ref(t)
    h = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(s.position, h, axis=0)[1:-1], s.velocity[1:-1],
                               atol=2e-5)
    # min-jerk blends have a jerk step at each start: the FD error there is ~h * jerk / 2
    np.testing.assert_allclose(np.gradient(s.velocity, h, axis=0)[1:-1], s.acceleration[1:-1],
                               atol=2e-2)
    assert s.position[0, 2] >= 0.05 and np.isfinite(s.position).all()


def test_reference_speeds():
    t = np.linspace(0.0, 30.0, 30001)
    def peak(name):
        return np.linalg.norm(make_reference(
            name, speed=2.0, duration=30.0)(t).velocity[:, :2], axis=1).max()
    assert peak("figure8") == pytest.approx(2.0, rel=1e-6)
    assert peak("lissajous") <= 2.0 + 1e-9
    assert peak("sweep") == pytest.approx(2.0, rel=1e-3)  # ramp ends at full speed
    with pytest.raises(InputError, match="unknown path"):
        make_reference("circle")


def test_hover_log_accelerometer_reads_plus_g():
    log, truth = generate_flight(PARAMS, "hover", None, None, seed=0, duration=0.5,
                                 control_period=0.01, engine="analytic")
    np.testing.assert_allclose(log.accel, np.tile([0, 0, PARAMS.gravity], (len(log), 1)),
                               atol=1e-6)
    np.testing.assert_allclose(log.position, np.tile([0, 0, 1.0], (len(log), 1)), atol=1e-6)
    assert truth["effects"] == [] and truth["path"]["name"] == "hover"


def test_specific_force_matches_differentiated_velocity():
    effects = effect_set_from_specs(["body_drag:cd_area=0.05", "wind:vx=3",
                                     "mass_offset:mass=0.05"])
    log, _ = generate_flight(PARAMS, "figure8", effects, None, seed=0, duration=1.0,
                             control_period=0.005, speed=2.0)
    accel_world = np.gradient(log.velocity, log.t, axis=0)
    accel_world[:, 2] += PARAMS.gravity
    expected = rotate_inverse(log.quat, accel_world)
    # central differences of a 200 Hz log: O(h^2) error, commands held per period
    np.testing.assert_allclose(log.accel[2:-2], expected[2:-2], atol=0.05)
    # the drag in the 3 m/s wind shows: specific force along body x is not zero
    assert np.abs(log.accel[:, 0]).max() > 0.1


def _synthetic(n=2001, dt=0.001):
    t = np.arange(n) * dt
    position = np.stack([np.sin(t), np.zeros(n), np.ones(n)], -1)
    return FlightLog(t=t, position=position, quat=euler_to_quat(np.stack(
        [np.zeros(n), np.zeros(n), 0.3 * t], -1)), body_rate=np.tile([0, 0, 0.3], (n, 1)),
        accel=np.tile([0, 0, 9.81], (n, 1)), rotor_speed=np.full((n, 4), 500.0),
        rotor_command=np.full((n, 4), 0.5), vbat=np.full(n, 4.0))


def test_sensor_noise_bias_and_quantisation():
    sensors = SensorModel(noise={"gyro": 0.02, "attitude": 0.01, "rotor": 5.0},
                          bias={"accel": 0.1, "gyro": -0.01},
                          quantization={"rotor": 10.0, "vbat": 0.1})
    true = _synthetic()
    measured = sensors.apply(true, seed=7)
    gyro_error = measured.body_rate - true.body_rate
    np.testing.assert_allclose(gyro_error.mean(0), -0.01, atol=3 * 0.02 / np.sqrt(2001))
    np.testing.assert_allclose(gyro_error.std(0), 0.02, rtol=0.06)
    relative = quat_multiply(quat_conjugate(true.quat), measured.quat)
    np.testing.assert_allclose((2 * relative[:, 1:]).std(0), 0.01, rtol=0.06)
    np.testing.assert_allclose(measured.accel, true.accel + 0.1)
    assert np.all(np.mod(measured.rotor_speed, 10.0) == 0.0)
    np.testing.assert_allclose(measured.vbat, 4.0)
    np.testing.assert_array_equal(measured.rotor_command, true.rotor_command)
    again = sensors.apply(true, seed=7)
    np.testing.assert_array_equal(again.body_rate, measured.body_rate)
    assert not np.array_equal(sensors.apply(true, seed=8).body_rate, measured.body_rate)


def test_sensor_rate_and_delay():
    true = _synthetic()
    measured = SensorModel(rate=100.0, delay=0.05).apply(true, seed=0)
    np.testing.assert_allclose(np.diff(measured.t), 0.01, atol=1e-12)
    later = measured.t > 0.05
    # logged value at t is the truth at t - delay (x = sin t; linear interpolation error)
    np.testing.assert_allclose(measured.position[later, 0], np.sin(measured.t[later] - 0.05),
                               atol=1e-6)


def test_sensor_flag_errors():
    assert parse_signal_values("position=0.001, gyro=0.01", flag="--n") == \
        {"position": 0.001, "gyro": 0.01}
    assert parse_signal_values("gyro=-0.01", flag="--b", signed=True) == {"gyro": -0.01}
    with pytest.raises(InputError, match="--n: unknown signal 'gps'"):
        parse_signal_values("gps=1", flag="--n")
    with pytest.raises(InputError, match="--n: gyro: must be finite and >= 0"):
        parse_signal_values("gyro=-1", flag="--n")
    with pytest.raises(InputError, match="rate: must be positive"):
        SensorModel(rate=0.0)


ARGS = ["--model", "physical", "--path", "figure8", "--speed", "1.0", "--duration", "0.5",
        "--control-period", "0.01", "--effect", "ground_effect:gain=1.5",
        "--effect", "motor_lag:time_constant=0.03", "--sensor-noise", "position=1e-3,gyro=0.01",
        "--sensor-bias", "accel=0.05", "--seed", "3"]


def test_cli_is_deterministic_and_writes_truth_sidecar(tmp_path, capsys):
    outputs = []
    for name in ("a", "b"):
        path = tmp_path / name / "flight.csv.gz"
        path.parent.mkdir()  # outputs never create folders
        assert main(ARGS + ["-o", str(path)]) == 0
        outputs.append((path.read_bytes(), truth_path(path).read_bytes()))
    assert outputs[0] == outputs[1]
    truth = json.loads(outputs[0][1])
    assert [e["name"] for e in truth["effects"]] == ["ground_effect", "motor_lag"]
    assert truth["effects"][0]["values"]["gain"] == 1.5
    assert truth["sensors"]["noise_std"] == {"gyro": 0.01, "position": 0.001}
    log = load_log(tmp_path / "a" / "flight.csv.gz")
    assert len(log) == 51 and log.rotor_count == 4
    # blind: nothing about the effects is in the log itself
    header = __import__("gzip").decompress(outputs[0][0]).split(b"\n")[0]
    assert b"ground" not in header and b"lag" not in header


@pytest.mark.parametrize("extra, message", [
    (["--effect", "ground_efect:gain=1"], "unknown effect"),
    (["--effect", "ground_effect:gain=99"], "outside the plausible range"),
    (["--sensor-noise", "gyro=x"], "'x' is not a number"),
    (["--model", "no_such_model"], "no_such_model"),
])
def test_cli_bad_input_one_line_nothing_written(tmp_path, capsys, extra, message):
    out = tmp_path / "flight.csv"
    assert main(ARGS + extra + ["-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert not out.exists() and not truth_path(out).exists()


def test_geometric_controller_tracks_and_rejects_payload():
    effects = effect_set_from_specs(["mass_offset:mass=0.08"])
    for chosen in (EffectSet(), effects):
        log, _ = generate_flight(PARAMS, "figure8", chosen, None, seed=0, duration=2.0,
                                 control_period=0.01, speed=1.0)
        ref = make_reference("figure8", speed=1.0)(log.t)
        error = np.linalg.norm(log.position - ref.position, axis=1)
        assert error.max() < (0.05 if not chosen.effects else 0.25)
