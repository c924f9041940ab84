"""The Genesis flight source (benchmarks.genesis_source, genesis_cases): the vehicle
file's numbers in SI, the DC motor at hover, the file's rotor drag as quadsim's rotor drag,
the frozen case list, and -- with Genesis importable by ``QUADSIM_GENESIS_PYTHON`` (or this
interpreter: ``pip install -e '.[genesis]'`` after torch's CPU wheel) -- one short
flight pair checked against quadsim's own rigid-body and rotor model (frames, the RACE yaw
sign as quadsim's spins). CI does not install Genesis (torch); the flight test skips
there."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.genesis_cases import (
    motor_time_constant,
    shared_effects,
)
from benchmarks.genesis_source import (
    MODEL,
    MOTOR,
    FlightSpec,
    duty_for,
    genesis_available,
    hover_speed_of,
    rotor_drag_force,
    vehicle_params,
)


def test_vehicle_file_numbers_in_si():
    """racer.urdf's kf 8.47e-9 N/rpm^2 and km 2.13e-11 N m/rpm^2 are b 7.724e-7 N s^2 and d
    1.942e-9 N m s^2 per rad^2/s^2 ((60 / 2 pi)^2 = 91.19); hover (0.83 kg) at 1623 rad/s =
    15 500 rpm (kf rpm^2 x 4 = m g, 1e-12); the 2400 KV motor on 14.8 V needs a duty of 0.442
    there (k_e W + R d W^2 / k_e = 6.55 V) and lags 34.4 ms (J / (k_e^2 / R + 2 d W))."""
    assert MODEL["b"] == pytest.approx(7.724e-7, rel=1e-3)
    assert MODEL["d"] == pytest.approx(1.942e-9, rel=1e-3)
    w = hover_speed_of()
    rpm = w * 60 / (2 * np.pi)
    assert 4 * 8.47e-9 * rpm ** 2 == pytest.approx(0.83 * 9.81, rel=1e-12)
    assert w == pytest.approx(1623, abs=1)
    volts = MODEL["k_emf"] * w + MODEL["resistance"] * MODEL["d"] * w ** 2 / MODEL["k_emf"]
    assert volts == pytest.approx(6.55, abs=0.01)
    assert duty_for(w) == pytest.approx(volts / 14.8, rel=1e-12)
    assert MOTOR.steady_speed(duty_for(w), MODEL["d"]) == pytest.approx(w, rel=1e-9)
    assert motor_time_constant() == pytest.approx(0.0344, abs=2e-4)
    params = vehicle_params()
    assert params.rotor_count == 4 and params.thrust_factor == MODEL["b"]


def test_the_files_rotor_drag_is_quadsims_rotor_drag():
    """rotor_drag_force (the file's k_xy, k_z times the summed rotor speeds) is quadsim's
    ``rotor_drag`` effect with in-plane and axial coefficients k_xy, k_z at a level attitude
    (the body-frame air velocity (1, -2, 0.5) m/s, speeds 1500-1700 rad/s; 1e-12)."""
    from quadsim.effects.rotor_drag import rotor_drag_forces

    air = np.array([1.0, -2.0, 0.5])
    speeds = np.array([1500.0, 1600.0, 1650.0, 1700.0])
    ours = rotor_drag_forces(air[None], speeds[None], vehicle_params().rotor_axes,
                             MODEL["drag_xy"], MODEL["drag_z"]).sum(axis=1)[0]
    np.testing.assert_allclose(rotor_drag_force(air, speeds), ours, rtol=1e-12)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 28 frozen cases (quadcopter-sim's table), mapped to the library on top of the
    shared motor lag and rotor drag, within the table's ranges, the payload 40-120 g
    (``_helpers.check_motor_case_list``)."""
    from benchmarks import genesis_cases
    from benchmarks.tests._helpers import check_motor_case_list

    assert [e.name for e in shared_effects()] == ["motor_lag", "rotor_drag"]
    check_motor_case_list(genesis_cases, ("motor_lag", "rotor_drag"), MODEL["mass"],
                          float(np.hypot(*MODEL["positions"][0])), payload_kg=(0.04, 0.12))


@pytest.mark.skipif(not genesis_available(), reason="Genesis is not importable "
                    "(QUADSIM_GENESIS_PYTHON)")
def test_flights_agree_with_quadsims_model():
    """A nominal flight (2.1 s logged) and a +0.1 kg flight (0.5 s) in one Genesis worker,
    checked by ``_helpers.check_source_flight`` against quadsim's model with the shared
    motor lag and rotor drag (Genesis' world angular velocity turned into body rates, the
    RACE yaw sign as quadsim's spins: the yaw torque's residual is checked on its own)."""
    from benchmarks.genesis_source import genesis_flights
    from benchmarks.tests._helpers import check_source_flight

    base = FlightSpec(seed=5, speed=0.8, duration=2.1)
    heavy = FlightSpec(seed=6, speed=0.8, duration=0.5, effects={"mass": 0.1})
    (log, truth), (log_heavy, _) = genesis_flights([base, heavy], workers=1)
    assert truth["effects"] == {} and truth["source"] == "genesis"
    params = vehicle_params()
    check_source_flight(log, log_heavy, params, 0.1, shared_effects(),
                        float(np.hypot(*MODEL["positions"][0])))
    # the yaw torque: within 5 % of one rotor's hover drag torque d W_h^2 (5.1 mN m) RMS
    # (measured 0.17 mN m on a 4 s flight; with the spins flipped 4.0 mN m)
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    r = residuals(prepare([log], params)[0].fit, params, shared_effects(), rotor_channel=False)
    assert np.sqrt(np.mean(r[:, 5] ** 2)) < 0.05 * MODEL["d"] * hover_speed_of() ** 2


def test_no_genesis_is_one_error_line(tmp_path, monkeypatch, capsys):
    """``QUADSIM_GENESIS_PYTHON`` naming no interpreter (or one without Genesis): not
    available, flying raises ModelError naming the interpreter, and ``--independent --source
    genesis --cache DIR`` ends with one error line, exit 2, nothing written into DIR."""
    import importlib.util
    from pathlib import Path

    from benchmarks.genesis_source import genesis_flights
    from quadsim.core.errors import ModelError

    monkeypatch.setenv("QUADSIM_GENESIS_PYTHON", str(tmp_path / "no-python"))
    assert not genesis_available()
    with pytest.raises(ModelError, match="no-python"):
        genesis_flights([FlightSpec(seed=1)])
    script_path = Path(__file__).resolve().parents[1] / "gap_benchmark.py"
    spec = importlib.util.spec_from_file_location("gap_benchmark_script", script_path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    cache = tmp_path / "cache"
    cache.mkdir()
    assert script.main(["--independent", "--source", "genesis", "--cache", str(cache)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --source genesis:"), err
    assert not any(cache.iterdir())
