"""Flights flown far *below* their references (issue 47): along a coordinate whose growth the
references do not measure, on each channel the flight drives under every reference, the
reference model's error need not shrink with the signal, and what a reading removes under the
references' typical mean square, up to t (1 - k^2), counts as that error
(quadsim.gap.reference.reach_of, "Below the references"; quadsim.gap.judge.extrapolation_share).
Closed forms; generated references flown alike and hard (an asymmetric motor lag the shared
model lacks) against gentle flights: no effect -> no confident name, +20 % mass and a 4 mm CoM
offset still named; the real Crazyflie flights (nominal flight_03 against ten plain mixed
flights)."""

from __future__ import annotations

import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.judge import beyond_reach, extrapolation_share, flights_share
from quadsim.gap.reference import (
    COORDINATES,
    PROPORTIONAL_SLOPE,
    REACH_Z,
    Envelope,
    Position,
    reach_of,
    slope_errors,
)
from quadsim.gap.words import reach_words

from _helpers import DRAG  # noqa: E402

C = 3

#: five references flown alike (within 2 %), their lack of fit scattering by 0.1 (log units)
ALIKE = np.log([[1.00, 1.00, 1.00], [1.01, 1.02, 1.01], [1.02, 0.99, 1.02],
                [0.99, 1.01, 0.99], [1.00, 1.00, 1.02]])
SCATTER = 0.1 * np.array([[1, -1, 0.5], [-1, 0.5, 1], [0.5, 1, -1], [-0.5, -0.5, -0.5],
                          [0.5, 0, 0]])


def _reference(coords, log_ms, excite):
    return SimpleNamespace(envelope=Envelope(np.asarray(coords, float), None,
                                             excite=np.asarray(excite, float)),
                           log_ms=np.asarray(log_ms, float), sigma=np.ones(C),
                           tau=np.full(C, 2.0),
                           lof_mean=np.asarray(log_ms, float).mean(axis=0))


def _place(coords, excite, refs_coords, samples=None):
    x = np.asarray(coords, float)
    excess = np.maximum(np.maximum(x - refs_coords.max(axis=0), refs_coords.min(axis=0) - x),
                        0.0)
    k = int(np.argmax(excess))
    return Position(x, float(excess[k]), COORDINATES[k][0], None, "",
                    excite=np.asarray(excite, float), samples=samples)


def test_a_gentle_flight_gets_the_allowance_under_the_typical_level():
    """References flown alike (their growth's slope not measured: 1.96 se > 2); a flight at
    0.3x their thrust variation driving channels 0 and 1 at 0.5x and 0.8x their smallest
    excitation, channel 2 at 1.5x their largest: under = log(1/k), allowance_under =
    t (1 - k^2) on 0 and 1, 0 on 2 (its allowance above t (1.5^2 - 1) as before); the
    effective samples N / tau."""
    ref = _reference(ALIKE, SCATTER, ALIKE)
    assert REACH_Z * slope_errors(ALIKE[:, 2], SCATTER)[0] > PROPORTIONAL_SLOPE
    k = np.array([0.5, 0.8, 1.5])
    excite = np.log(k) + np.array([ALIKE[:, 0].min(), ALIKE[:, 1].min(), ALIKE[:, 2].max()])
    flight = np.log([1.0, 1.0, 0.3])
    reach = reach_of(ref, _place(flight, excite, ALIKE, samples=1000))
    assert reach.coordinate == "thrust" and not reach.above
    assert reach.excess == pytest.approx(ALIKE[:, 2].min() - np.log(0.3), rel=1e-12)
    typical = np.exp(SCATTER.mean(axis=0))
    assert reach.under == pytest.approx([np.log(2.0), np.log(1.25), 0.0], rel=1e-12, abs=1e-15)
    assert reach.allowance_under == pytest.approx(
        typical * np.array([1 - 0.25, 1 - 0.64, 0.0]), rel=1e-12, abs=1e-15)
    assert reach.allowance == pytest.approx(typical * np.array([0.0, 0.0, 1.25]), rel=1e-12)
    assert reach.counts == pytest.approx(np.full(C, 500.0), rel=1e-12)


def test_no_allowance_under_unless_the_flight_is_below_along_an_unmeasured_coordinate():
    """A flight above the references in thrust variation (inside in speed and rate) that
    drives channel 0 gently: no coordinate below, so no allowance under (the rule above
    alone, as before); driving no channel beyond them either: no reach. References that
    measure their growth (spread 3x, lack of fit following it): a gentle flight within
    reach (None)."""
    ref = _reference(ALIKE, SCATTER, ALIKE)
    excite = np.log([0.5, 1.0, 3.0])
    reach = reach_of(ref, _place(np.log([1.0, 1.0, 3.0]), excite, ALIKE))
    assert reach.above and np.all(reach.allowance_under == 0.0) and np.all(reach.under == 0)
    assert reach_of(ref, _place(np.log([1.0, 1.0, 3.0]), np.log([0.5, 1.0, 1.0]), ALIKE)) \
        is None
    spread = np.log(np.outer([1.0, 1.3, 1.7, 2.2, 3.0], [1.0, 1.0, 1.0]))
    measured = _reference(spread, 0.8 * spread + 0.01 * SCATTER, spread)
    assert reach_of(measured, _place(np.log([0.3, 0.3, 0.3]), np.log([0.3] * C), spread)) \
        is None


def test_the_share_counts_what_a_reading_removes_under_the_typical_level():
    """Per channel s_c = max(0, min(m0_c, t_c) - m_c) within u_c = allowance_under, earned
    n_c min(s_c, u_c) / 2, added to the removal above t within its allowance: the IMU
    Crazyflie's log10 (inertia_error: Mx 0.558 -> 0.376, My 0.753 -> 0.583 under t 1.156,
    0.996; n 103, 84; margin 13.9 log units) gets f = 1; a payload whose gap lies far above
    the typical level keeps its margin."""
    typical = np.array([1.156, 0.996, 0.877])
    reach = SimpleNamespace(typical=typical, allowance=np.array([0.0, 0.0, 0.606]),
                            allowance_under=typical * (1 - np.array([0.668, 0.685, 1.0])),
                            counts=np.array([103.0, 84.1, 55.9]))
    null, inertia = [0.558, 0.753, 0.863], [0.376, 0.583, 0.863]
    earned = 0.5 * (103.0 * 0.182 + 84.1 * 0.170)
    assert earned > 13.9
    assert extrapolation_share(inertia, null, reach, 13.9) == 1.0
    assert extrapolation_share(inertia, null, reach, 2 * earned) == pytest.approx(0.5, rel=1e-9)
    # capped by the allowance under: channel 0 allowed 0.1 only
    capped = SimpleNamespace(**{**vars(reach), "allowance_under": np.array([0.1, 0.31, 0.0])})
    assert extrapolation_share(inertia, null, capped, 100.0) == \
        pytest.approx(0.5 * (103.0 * 0.1 + 84.1 * 0.170) / 100.0, rel=1e-9)
    # a +20 % mass on a gentle flight: Fz from 40 t to t; only what lies under t (nothing:
    # the reading leaves t) could be the model's error
    mass = SimpleNamespace(typical=np.ones(C), allowance=np.zeros(C),
                           allowance_under=np.full(C, 0.5), counts=np.full(C, 100.0))
    assert extrapolation_share([1.0, 1.0, 1.0], [1.0, 1.0, 40.0], mass, 1900.0) == 0.0
    # and one that goes on under it: 0.2 of 39.2 removed, 0.5 * 100 * 0.2 of the margin
    assert extrapolation_share([1.0, 1.0, 0.8], [1.0, 1.0, 40.0], mass, 1900.0) == \
        pytest.approx(10.0 / 1900.0, rel=1e-12)
    # without the counts: the share of what it removes (under the level counted as removed)
    plain = SimpleNamespace(**{**vars(mass), "counts": None})
    assert extrapolation_share([1.0, 1.0, 0.8], [1.0, 1.0, 40.0], plain) == \
        pytest.approx(0.2 / 39.2, rel=1e-12)
    # no allowance under (a stub of the rule above, or 0): exactly as before
    before = SimpleNamespace(typical=np.ones(C), allowance=np.zeros(C), counts=None)
    assert flights_share([([1.0, 1.0, 0.8], [1.0, 1.0, 40.0], before)]) == 0.0


def test_the_words_name_the_law_and_the_gentle_side():
    """Below: "at 0.35x the lowest of your references' ..." and the law that need not
    shrink; both allowances: both laws; the moved weight makes no difference the reading."""
    typical = np.ones(C)
    reach = SimpleNamespace(coordinate="rate", excess=float(np.log(1 / 0.35)), above=False,
                            ratio=6.1, allowance=np.zeros(C), allowance_under=typical / 2)
    rows, moved = beyond_reach(
        [("inertia_error", 0.99, SimpleNamespace(ms=np.array([0.4, 0.6, 0.9]), log_z=14.0)),
         ("no_difference", 0.01, SimpleNamespace(ms=np.array([0.6, 0.75, 0.9]), log_z=0.0))],
        SimpleNamespace(**vars(reach), typical=typical, counts=np.full(C, 100.0)))
    assert rows[0][0] == "no_difference" and rows[0][1] == pytest.approx(1.0)
    words = reach_words(reach, {k: (p, f, "") for k, (p, f) in moved.items()},
                        outcome="no_significant_gap")
    assert "at 0.35x the lowest of your references' RMS body rate" in words
    assert "need not shrink" in words and "growing in proportion" not in words
    assert "not sure" in words
    both = SimpleNamespace(**{**vars(reach), "allowance": np.array([0.0, 1.0, 0.0])})
    words = reach_words(both, {"x": (0.5, 1.0, "")}, outcome="no_significant_gap")
    assert "need not shrink" in words and "growing in proportion" in words


# --- generated: references flown alike and hard, gentle flights ----------------------------

#: one xdist worker runs the generated tests (their module fixtures are built once)
pytestmark = pytest.mark.xdist_group("test_reach_below")

#: every generated path speed here as a fraction of the one these tests were written at
#: (references at 2.0 and 1.5 m/s, the judged flight at 0.3 m/s): at 2.0 m/s the crazyflie21's
#: figure-8 held rotor speeds at a bound on every seed (93-340 samples), at 1.5 on four of
#: five; all scaled alike (the hard references at 1.2 m/s, where each seed's path is flown
#: exactly), every ratio between the flights is kept
SLOWER = 0.6


def _generated():
    from quadsim.effects import make_effect

    # a motor that spins down 4x slower than up: the shared model's one time constant lacks
    # it, and what that lack looks like depends on how hard the flight is flown
    return [make_effect("motor_lag", time_constant=0.008, time_constant_down=0.03),
            make_effect("rotor_drag", coefficient=DRAG)]


def _calibrated(speed: float):
    from benchmarks.synthetic import synthetic_flight
    from quadsim.core.errors import QuadsimWarning
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import prepare
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    logs = [synthetic_flight(cf, _generated(), duration=5.0, seed=s,
                             speed=SLOWER * (speed + 0.01 * s), flyable_only=True)
            for s in range(5)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return cf, calibrate(prepare(logs, cf), cf)


def _gentle(cf, reference, extra=(), speed=0.3):
    from benchmarks.synthetic import synthetic_flight
    from quadsim.gap.diagnose import judge_one

    log = synthetic_flight(cf, _generated() + list(extra), duration=5.0, seed=20,
                           speed=SLOWER * speed, flyable_only=True)
    return judge_one(log, reference)


@pytest.fixture(scope="module")
def hard():
    """Five references flown alike at path speeds 1.20-1.22 m/s (2.00-2.04 x SLOWER)."""
    return _calibrated(2.0)


@pytest.fixture(scope="module")
def brisk():
    """Five references flown alike at path speeds 0.90-0.92 m/s (1.50-1.54 x SLOWER)."""
    return _calibrated(1.5)


def test_a_gentle_flight_with_no_effect_gets_no_confident_name(hard):
    """A flight flown far more gently than its references (0.18 m/s path speed against
    1.2 m/s; the shared model's asymmetric motor lag and rotor drag alike): no difference,
    stated at >= 0.9, and the answer says it was flown outside the references' envelope at
    its own RMS speed. On references whose rotors a path held at a bound (before the
    generated flights were made exact) main 51e2cb8 named battery_sag here (94 %,
    tentative): the rule that keeps a margin earned under the references' typical level
    from naming (``judge.extrapolation_share``) is tested on its numbers above and on real flights
    below; on these exact flights no reading earns such a margin (measured: 100 %)."""
    cf, reference = hard
    entry = _gentle(cf, reference)
    assert entry["outcome"] == "no_significant_gap", entry["answer"]
    assert entry["probability"] > 0.9, entry["answer"]
    envelope = entry["envelope"]
    assert envelope["outside"], envelope
    assert envelope["rms"]["speed"] < 0.3, envelope      # 0.18 m/s path, RMS 0.24 m/s
    assert f"RMS speed {envelope['rms']['speed']:.3g} m/s" in entry["answer"], entry["answer"]
    assert "battery_sag" not in entry["answer"], entry["answer"]


def test_a_real_change_on_a_gentle_flight_is_still_named(brisk):
    """Against references at 0.9 m/s: a gentle (0.18 m/s) flight without effect is no
    difference (main: 58 %, battery_sag 38 %; now above 90 %, not sure); +20 % mass is
    named mass_offset at its size (main 59 %, now 56 %: the thrust curve its rival, as
    main), a 4 mm CoM offset com_offset (main > 99 %, now above 90 %) at its size."""
    from quadsim.effects import make_effect

    cf, reference = brisk
    plain = _gentle(cf, reference)
    assert plain["outcome"] == "no_significant_gap" and plain["probability"] > 0.9, \
        plain["answer"]
    mass = 0.2 * cf.mass
    entry = _gentle(cf, reference, [make_effect("mass_offset", mass=mass)])
    assert entry["verdict"] == "mass_offset" and entry["probability"] > 0.5, entry["answer"]
    assert entry["params"]["mass_offset.mass"] == pytest.approx(mass, rel=0.05)
    entry = _gentle(cf, reference, [make_effect("com_offset", x=0.004, y=0.0)])
    assert entry["verdict"] == "com_offset" and entry["probability"] > 0.9, entry["answer"]
    assert entry["params"]["com_offset.x"] == pytest.approx(0.004, rel=0.1)


DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "crazyflie21_brushless"
PLAIN = (100, 101, 103, 104, 114, 115, 118, 120, 121, 124)


@pytest.mark.skipif(not (DATA / "mixed" / "flight_100.csv.gz").exists(),
                    reason="needs ../shared/data/crazyflie21_brushless")
def test_a_nominal_flight_far_below_ten_plain_references_is_not_named():
    """The ten plain mixed flights as references, nominal flight_03 (0.19x their thrust
    variation, 0.71x their RMS speed, in which their growth is not measured): main 51e2cb8
    named blade_flapping 99 % (tentative); its margin (8.5 log units) comes from Mx, My under
    the references' typical level. The rule below the references alone: no_significant_gap
    76 %, not sure; with the placed model holding the shared values where the references do
    not measure their trend (``reference.Trend.measured``) no reading earns there:
    no_significant_gap 99 %; outside their envelope no difference only as far as the data
    carry it (``judge.sure_null``: thrust_mismatch's interval reaches beyond the references'
    band): 73 %, not sure, more than half the weight carried. Either way no name, and "not
    sure" said wherever it is tentative."""
    from quadsim.core.errors import QuadsimWarning
    from quadsim.gap import diagnose_per_flight
    from quadsim.logs.flightlog import load_log
    from quadsim.vehicle.params import load_params

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [load_log(DATA / "mixed" / f"flight_{i}.csv.gz") for i in PLAIN]
        flights = [load_log(DATA / "nominal" / "flight_03.csv.gz")]
        result = diagnose_per_flight(flights, refs, load_params("crazyflie21"))
    entry = result.flights[0]
    assert entry.outcome == "no_significant_gap" and entry.probability > 0.5, entry.answer
    assert not entry.tentative or ("need not shrink" in entry.answer
                                   and "not sure" in entry.answer) or (
        "Not sure: flown beyond the reference flights" in entry.answer), entry.answer


IMU = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "crazyflie21_imu_cmd"


@pytest.mark.skipif(not (IMU / "log10").exists(),
                    reason="needs ../shared/data/crazyflie21_imu_cmd")
def test_an_imu_flight_below_its_two_references_is_not_named(tmp_path):
    """Commands only, one Crazyflie: log10 against log15 and log16 (0.35x their RMS body rate;
    two references measure no growth). main 51e2cb8 named inertia_error 99 % (I_xx +101 %);
    its margin (13.9 log units) comes from Mx, My under the references' typical level:
    no_significant_gap, not sure."""
    import json

    from quadsim.gap.__main__ import main as gap_main
    from quadsim.identify.__main__ import main as identify_main

    root = Path(__file__).resolve().parents[1]
    model, out = tmp_path / "cf.toml", tmp_path / "log10.json"
    logs = [str(IMU / name) for name in ("log10", "log15", "log16")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert identify_main(["--logs", *logs, "--vehicle",
                              str(root / "docs" / "examples" / "cf_imu_skeleton.toml"),
                              "-o", str(model)]) == 0
        assert gap_main(["--model", str(model), "--per-flight", logs[0], "--reference",
                         *logs[1:], "--workers", "1", "--cache-dir", str(tmp_path / "c"),
                         "--json", str(out)]) == 0
    entry = json.loads(out.read_text())["flights"][0]
    assert entry["outcome"] == "no_significant_gap" and entry["tentative"], entry["answer"]
    assert "need not shrink" in entry["answer"] and "inertia_error" in entry["answer"]
