"""The shipped crazyflie21 set carries the motor time constant its nominal flights determine
(issue 47 item 6): ``motor_map.time_constant`` written by ``scripts/identify_crazyflie.py``
with ``identify --logs``' own motor fit, and the same lag in its effect file
``models/effects/crazyflie21_nominal.toml`` as ``motor_lag``, read there by another route
(``quadsim.gap``'s evidence on the rotor channel, flight_00..03 with flight_04 held out)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from quadsim.effects.effectfile import load_effect_file
from quadsim.vehicle.params import load_params

from _helpers import load_script

ROOT = Path(__file__).resolve().parents[1]
SET = ROOT / "models" / "crazyflie21.toml"
EFFECTS = ROOT / "models" / "effects" / "crazyflie21_nominal.toml"
DATA = ROOT.parent / "shared/data/crazyflie21_brushless"


def _effects_lag():
    (lag,) = [e for e in load_effect_file(EFFECTS).effects.effects if e.name == "motor_lag"]
    return lag


def test_the_set_carries_its_motor_time_constant():
    """50 ms on identify's 2.5 ms grid (per flight 45-57.5 ms), with its unit and source
    (0, the default, would mean the rotors follow their commands at once)."""
    params = load_params("crazyflie21")
    assert params.motor_map.time_constant == pytest.approx(0.050, abs=1e-9)
    source = params.sources["motor_map.time_constant"]
    assert "identify --logs' motor fit" in source and "20 nominal flights" in source
    assert "per flight 0.0450-0.0575 s" in source


def test_the_set_and_its_effect_file_read_one_lag():
    """Two routes to one physical lag: the set's (least squares on the lagged command map,
    all 20 flights) and the effect file's (the gap's evidence on flights 00-03, 04 held
    out) agree within the effect file's 95 % interval, and each lies in the 10-60 ms of
    micro motors (quadsim.effects.motor_lag's spread)."""
    lag = _effects_lag()
    tau_set = load_params("crazyflie21").motor_map.time_constant
    ci = float(load_effect_file(EFFECTS).sources[("motor_lag", "time_constant")]
               .split("+- ")[1].split(" ")[0])
    assert lag.time_constant == pytest.approx(0.05153, rel=1e-3)
    assert abs(lag.time_constant - tau_set) < ci
    assert lag.time_constant_down == 0.0            # one time constant, as the set's
    for tau in (lag.time_constant, tau_set):
        assert 0.010 < tau < 0.060


def test_the_script_reads_a_known_lag(tmp_path):
    """Generated flights whose rotors lag their commands by exactly 40 ms: the script's
    :func:`motor_lag` (identify's fit on the logs as written) reads 40 ms, pooled and per
    flight."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.effects import make_effect
    from quadsim.logs.flightlog import write_log

    cf = load_params("crazyflie21")
    paths = [Path(write_log(tmp_path / f"f{s}.csv", synthetic_flight(
        cf, [make_effect("motor_lag", time_constant=0.04)], seed=s, duration=4.0)))
        for s in (1, 2)]
    lag = load_script("identify_crazyflie").motor_lag(paths)
    assert lag.tau == pytest.approx(0.040, abs=1e-9)
    assert lag.ci95[0] <= 0.040 <= lag.ci95[1]
    np.testing.assert_allclose(lag.per_flight, 0.040, atol=1e-9)


@pytest.mark.skipif(not (DATA / "nominal").is_dir(), reason="shared data absent")
def test_the_committed_set_is_what_the_script_writes():
    """models/crazyflie21.toml equals a fresh rendering from nominal/ (never a hand edit),
    and its time constant lies within the per-flight fits' mean +- 2 standard errors."""
    script = load_script("identify_crazyflie")
    nominal = sorted((DATA / "nominal").glob("flight_*.csv.gz"))
    lag = script.motor_lag(nominal)
    assert SET.read_text(encoding="utf-8") == script.render(script.identify(nominal), lag)
    per = np.array(lag.per_flight)
    assert len(per) == 20
    assert abs(lag.tau - per.mean()) < 2 * per.std(ddof=1) / np.sqrt(len(per))


def test_the_set_carries_its_battery_voltage_law():
    """The map's speed per command follows the battery: ``voltage_gain`` 0.249 1/V about
    ``reference_voltage`` 3.71 V (the nominal flights' median, inside a 1S LiPo's 3.3-4.2 V),
    both with unit and source; the nano-drone set, the same motors identified by ``identify
    --logs`` from other flights, reads 0.257 (per-rotor spread 0.015): one law."""
    mm = load_params("crazyflie21").motor_map
    nano = load_params(ROOT / "models" / "nanodrone_cf21bl.toml").motor_map
    assert mm.voltage_gain == pytest.approx(0.249, abs=5e-4)
    assert 3.3 < mm.reference_voltage < 4.2
    assert abs(mm.voltage_gain - nano.voltage_gain) < 0.015
    sources = load_params("crazyflie21").sources
    assert "voltage gain" in sources["motor_map.voltage_gain"]
    assert "median battery voltage" in sources["motor_map.reference_voltage"]


@pytest.mark.skipif(not (DATA / "nominal").is_dir(), reason="shared data absent")
def test_the_map_gives_the_nominal_flights_rotor_speeds_from_their_commands():
    """The set's map through its lag, driven by each nominal flight's commands and battery
    voltage, against the speeds logged (airborne samples): at most 12 rad/s RMS on every
    flight (0.75 % of the ~1580 rad/s hover speed; measured 6.6-9.2), and the same map with
    its voltage law removed at least twice that in the median (measured 21 rad/s): the law
    carries what the flights show as the battery falls."""
    import dataclasses
    import warnings

    from quadsim.gap.logcheck import command_model_from_params
    from quadsim.logs.flightlog import load_log

    params = load_params("crazyflie21")
    flat = dataclasses.replace(params, motor_map=dataclasses.replace(params.motor_map,
                                                                    voltage_gain=0.0))
    rms = {}
    for label, p in (("law", params), ("flat", flat)):
        model, rms[label] = command_model_from_params(p), []
        for path in sorted((DATA / "nominal").glob("flight_*.csv.gz")):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                log = load_log(path)
            err = log.rotor_speed - model.speeds(log.t, log.rotor_command, log.vbat)
            air = np.mean(log.rotor_speed, axis=1) > 800.0
            rms[label].append(float(np.sqrt(np.mean(err[air] ** 2))))
    assert len(rms["law"]) == 20 and max(rms["law"]) < 12.0, rms["law"]
    assert np.median(rms["flat"]) > 2.0 * np.median(rms["law"]), rms
