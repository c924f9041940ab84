"""Helpers shared by the simulator sources' tests (not a test module)."""

from __future__ import annotations


def check_source_flight(log, heavy_log, params, extra_mass: float, shared: list,
                        arm: float) -> None:
    """A simulator source's short flights against quadsim's own rigid-body and rotor model:
    500 Hz, scalar-first unit quaternions near level, commands in 0..1; the logged rotor
    speeds in quadsim's rotor model (b, d, layout, spins) reproduce the logged specific
    force: the mean thrust is the accelerometer's body z force (1 %) and about the weight
    (5 %: the path climbs and tilts; each flight with its own mass); on the nominal flight
    quadsim's residual wrench with the source's ``shared`` physics stays below 1.5 % of the
    weight (forces) and 1.5 % of weight x ``arm`` (torques) RMS."""
    import numpy as np
    import pytest

    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    assert log.t[1] == pytest.approx(1.0 / 500)
    assert np.all(log.quat[:, 0] > 0.9)
    np.testing.assert_allclose(np.linalg.norm(log.quat, axis=1), 1.0, atol=1e-9)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))
    for flight, mass in ((log, params.mass), (heavy_log, params.mass + extra_mass)):
        thrust = params.thrust_factor * np.sum(flight.rotor_speed ** 2, axis=1)
        assert np.mean(flight.accel[:, 2]) * mass == pytest.approx(np.mean(thrust), rel=0.01)
        assert np.mean(thrust) == pytest.approx(mass * params.gravity, rel=0.05)
    weight = params.mass * params.gravity
    flight = prepare([log], params)[0]
    r = residuals(flight.fit, params, shared, rotor_channel=False)
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    assert np.all(rms[:3] < 0.015 * weight), rms
    assert np.all(rms[3:6] < 0.015 * weight * arm), rms


def check_case_table(module, counts: tuple[int, int, int], shared: tuple[str, ...]) -> list:
    """A source's frozen case table (``module``: its cases module) and what every source's
    shares: the same on a second draw; ``counts`` (no-effect, in-library, outside) cases;
    seeds apart from the references'; each in-library truth (not a delay) a library effect
    named by its true difference (:func:`module.library_truth`) on top of the ``shared``
    effects, in that order. Returns the cases (for the source's own range checks)."""
    from quadsim.effects import EFFECTS

    cases = module.case_list()
    assert module.case_list() == cases and len(cases) == sum(counts)
    kinds = [c["kind"] for c in cases]
    assert (kinds.count("none"), kinds.count("library"), kinds.count("outside")) == counts
    assert not {c["seed"] for c in cases} & {s.seed for s in module.reference_specs()}
    for case in cases:
        if case["kind"] == "library" and case["truth"] != "rotor_delay":
            names = [x.name for x in module.library_truth(case)]
            assert tuple(names[:len(shared)]) == tuple(shared), names
            assert case["truth"] in EFFECTS and case["truth"] in names
    return cases


def quiet_flight(flights, source: str):
    """A 1-s nominal flight of a source without sensor noise (``flights``: the source's
    ``*_flights(specs, workers=)``, ``FlightSpec`` its module's; seed 4): its log, checked
    to be the ``source``'s and 500 samples long, and the body-frame velocity (m/s, (N, 3))."""
    import importlib

    import numpy as np

    from benchmarks.simlog import Sensors
    from quadsim.core.frames import quat_to_rotmat

    spec = importlib.import_module(flights.__module__).FlightSpec
    quiet = Sensors(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    [(log, truth)] = flights([spec(seed=4, duration=1.0, sensors=quiet)], workers=1)
    assert truth["source"] == source and len(log.t) == 500
    return log, np.einsum("nji,nj->ni", quat_to_rotmat(log.quat), log.velocity)


def check_drawn(cases: list, mass: float, arm: float, bounds: dict) -> None:
    """Each case's drawn changes within a source's table (``bounds``: key -> (low, high),
    inclusive): ``mass`` as a share of the vehicle's ``mass`` (kg), ``com`` by its distance
    from the centre as a share of ``arm`` (m), ``wind`` by its speed (m/s), ``payload`` a
    pair of ranges: its mass (kg) and its offset's distance (m); any other key's value
    itself (``motor_tau`` s, ``motor_slow``, ``drag_scale`` factors)."""
    import numpy as np

    for case in cases:
        for key, value in case["effects"].items():
            if key not in bounds:
                continue
            if key == "payload":
                (m_lo, m_hi), (r_lo, r_hi) = bounds[key]
                assert m_lo <= value[0] <= m_hi and r_lo <= np.hypot(*value[1:3]) <= r_hi, case
                continue
            size = {"mass": lambda v: v / mass, "com": lambda v: np.hypot(*v) / arm,
                    "wind": lambda v: np.hypot(*v)}.get(key, float)(value)
            low, high = bounds[key]
            assert low <= size <= high, case


def check_motor_case_list(module, shared: tuple[str, str], mass: float, arm: float,
                          payload_kg: tuple[float, float] | None = None) -> None:
    """A DC-motor source's frozen cases (``module``: its cases module; the table
    ``benchmarks.sim_cases.MOTOR_TABLE``): 28, the same on a second draw; 6 no-effect,
    18 in-library, 4 outside; seeds apart from the references'; each in-library truth (not
    a delay) is a library effect named by its true difference on top of the ``shared`` two
    effects; the drawn changes within the table's ranges (mass +5..+20 % of ``mass``, CoM
    3-10 % of ``arm``, motor J x 1.5-2.5, wind 2-5 m/s, the payload in ``payload_kg``)."""
    import numpy as np

    from quadsim.effects import EFFECTS

    cases = module.case_list()
    assert module.case_list() == cases and len(cases) == 28
    kinds = [c["kind"] for c in cases]
    assert (kinds.count("none"), kinds.count("library"), kinds.count("outside")) == (6, 18, 4)
    assert not {c["seed"] for c in cases} & {s.seed for s in module.reference_specs()}
    for case in cases:
        e = case["effects"]
        if case["kind"] == "library" and case["truth"] != "rotor_delay":
            names = [x.name for x in module.library_truth(case)]
            assert tuple(names[:2]) == shared, names
            assert case["truth"] in EFFECTS and (case["truth"] in names or len(names) == 2)
        if "mass" in e:
            assert 0.05 <= e["mass"] / mass <= 0.2
        if "payload" in e and payload_kg is not None:
            assert payload_kg[0] <= e["payload"][0] <= payload_kg[1]
        if "com" in e:
            assert 0.03 <= np.hypot(*e["com"]) / arm <= 0.1
        if "motor_slow" in e:
            assert 1.5 <= e["motor_slow"] <= 2.5
        if "wind" in e:
            assert 2.0 <= np.hypot(*e["wind"]) <= 5.0
