"""Per-flight observability (benchmarks.observe) and the per-flight protocol of the
RotorPy and sensor-pipeline cases (benchmarks.cases): reference speeds, true models,
the flight cache."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from benchmarks import cases
from benchmarks.observe import OBSERVABLE, TrueModel, per_flight_observability, true_model
from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.effects import make_effect
from quadsim.vehicle.params import load_params

#: one xdist worker runs this module's tests (pytest-xdist --dist loadgroup): its module-scoped
#: fixtures are built once, not once per worker
pytestmark = pytest.mark.xdist_group("test_bench_observe")


@pytest.fixture(scope="module")
def observed():
    """Crazyflie, exact generated flights (sensor noise only) against 4 nominal ones: a +10 %
    mass, a +0.001 % mass, and a nominal flight; returns (observed, mass of the vehicle)."""
    params = load_params("crazyflie21")
    kw = {"duration": 4.0, "rate_hz": 250.0}
    refs = [synthetic_flight(params, [], seed=40 + k, speed=0.8 + 0.15 * k, **kw)
            for k in range(4)]
    big = [make_effect("mass_offset", mass=0.1 * params.mass)]
    tiny = [make_effect("mass_offset", mass=1e-5 * params.mass)]
    logs = [synthetic_flight(params, big, seed=50, **kw),
            synthetic_flight(params, tiny, seed=51, **kw),
            synthetic_flight(params, [], seed=52, **kw)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return per_flight_observability(logs, refs, params, [],
                                        [TrueModel(tuple(big)), TrueModel(tuple(tiny)), None])


def test_an_added_mass_is_observable_in_its_flight(observed):
    """+10 % mass: the true model leaves only the sensor noise, so it cuts the flight's
    normalised residual by >= 90 %, and the flight's gap is > 5x the references' own."""
    assert observed[0].reduction >= 0.9
    assert observed[0].gap > 5.0


def test_a_negligible_mass_is_not_observable(observed):
    """+0.001 % mass (0.4 mg on 37 g): below the noise, the cut stays under OBSERVABLE and
    the flight's gap is the references' own within 30 %."""
    assert observed[1].reduction < OBSERVABLE
    assert observed[1].gap == pytest.approx(1.0, abs=0.3)


def test_a_flight_without_library_truth_has_no_reduction(observed):
    """No true model (no effect): reduction exactly 0, gap the references' own within 30 %."""
    assert observed[2].reduction == 0.0
    assert observed[2].gap == pytest.approx(1.0, abs=0.3)


def test_true_model_replaces_shared_physics_of_the_same_name():
    """A slower motor replaces the shared nominal motor lag; other shared effects stay."""
    shared = [make_effect("motor_lag", time_constant=0.005),
              make_effect("rotor_drag", coefficient=1e-6)]
    slow = make_effect("motor_lag", time_constant=0.04)
    mass = make_effect("mass_offset", mass=0.01)
    assert true_model(shared, [slow, mass]) == (shared[1], slow, mass)
    assert true_model(shared, []) == tuple(shared)


def test_rotorpy_truth_is_its_nominal_motors_with_the_difference():
    """RotorPy's references share 5 ms motors: a mass case's true model is that lag plus the
    drawn mass; a motor-lag case's is its own time constant alone; a no-effect case has none."""
    from benchmarks.rotorpy_source import NOMINAL_TAU_M

    rows = cases.case_list()
    mass = next(c for c in rows if c["source"] == "rotorpy" and c["truth"] == "mass_offset")
    lag = next(c for c in rows if c["source"] == "rotorpy" and c["truth"] == "motor_lag")
    none = next(c for c in rows if c["source"] == "rotorpy" and c["truth"] == "none")
    names = [e.name for e in cases.per_flight_truth(mass).effects]
    assert names == ["motor_lag", "mass_offset"]
    assert cases.per_flight_truth(mass).effects[0].values()["time_constant"] == NOMINAL_TAU_M
    [effect] = cases.per_flight_truth(lag).effects
    assert effect.name == "motor_lag" and effect.values()["time_constant"] >= 0.02
    assert cases.per_flight_truth(none) is None


def test_references_span_the_first_flights_speeds():
    """Every case's first flight is flown at a path speed inside the references' range, and
    the 8 references are evenly spread over 0.65-1.5."""
    speeds = cases.reference_speeds()
    assert len(speeds) == cases.REFERENCES == 8
    np.testing.assert_allclose(np.diff(speeds), (1.5 - 0.65) / 7, rtol=1e-12)
    first = [cases._case_setup(c)[2] for c in cases.case_list()]
    assert speeds.min() <= min(first) and max(first) <= speeds.max()


def test_first_flight_is_flown_once_and_reused_by_the_full_case(tmp_path, monkeypatch):
    """first_flight flies one flight and caches it; case_flights then flies only the others
    and stores all of them under the held-out key (the case's five fields, as before);
    first_flight then reads the full entry. A stand-in source records each flight."""
    flown = []

    def fly(source, params, spec, seed, speed):
        flown.append(seed)
        return (source, seed, round(speed, 12))

    monkeypatch.setattr(cases, "_fly", fly)
    monkeypatch.setenv(cases.CACHE_ENV, str(tmp_path))
    case = cases.case_list()[40]
    assert cases.case_key(case) == {k: case[k] for k in ("source", "vehicle", "truth", "kind",
                                                         "seed")}
    _, first = cases.first_flight(case)
    assert flown == [case["seed"] * 10]
    _, logs = cases.case_flights(case)
    assert flown == [case["seed"] * 10 + s for s in range(cases.FLIGHTS)]
    assert logs[0] == first and len(logs) == cases.FLIGHTS
    assert cases.first_flight(case)[1] == first and len(flown) == cases.FLIGHTS
    assert cases.is_cached(cases.case_key(case))
