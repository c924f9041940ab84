"""Several take-offs in one log (issue 44, item 4): ``gap`` and ``view`` keep every airborne
stretch as a segment of the one flight, and nothing bridges the ground span between them.

A generated closed-loop flight (quadsim.logs.generate, MuJoCo) with a mass offset is cut in
two at 2.5 s and a 2 s ground span (motors off, at rest, specific force g) is put between the
halves: the states jump there. Checked: both stretches kept with their sample counts, the
prepared states equal those of each stretch prepared alone and then joined, and the per-flight
verdict does not move when the ground span between the stretches holds other numbers."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from quadsim.core.errors import QuadsimWarning
from quadsim.effects import EffectSet, make_effect
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import interior, judge_one, prepare
from quadsim.gap.residual import flight_states
from quadsim.logs.checks import check_log, check_logs
from quadsim.logs.flightlog import ARRAYS, FlightLog
from quadsim.logs.generate import generate_flight
from quadsim.logs.sensors import SensorModel
from quadsim.vehicle.params import load_params

NOISE = SensorModel(noise={"position": 5e-4, "velocity": 0.01, "attitude": 2e-3,
                           "gyro": 0.02, "accel": 0.1, "rotor": 10.0})
DURATION = 5.0
GROUND_S = 2.0

pytestmark = pytest.mark.xdist_group("test_takeoffs")


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def flown(cf):
    """(two-take-off log, its two stretches as logs, the references' model)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [generate_flight(cf, path, EffectSet(()), NOISE, seed, duration=DURATION,
                                speed=1.0)[0]
                for seed, path in enumerate(("figure8", "steps", "lissajous"))]
        reference = calibrate(prepare(refs, cf), cf)
        log, _ = generate_flight(cf, "figure8", EffectSet((make_effect(
            "mass_offset", mass=0.004),)), NOISE, 7, duration=DURATION, speed=1.0)
    half = int(np.searchsorted(log.t, 2.5))
    first, second = log.take(slice(0, half)), log.take(slice(half, len(log.t)))
    return first, second, reference


def _with_ground(first: FlightLog, second: FlightLog, *, z: float, vbat: float) -> FlightLog:
    """``first``, a GROUND_S ground span (motors off, at rest at height ``z``), ``second``
    moved GROUND_S later."""
    dt = float(np.median(np.diff(first.t)))
    t_ground = first.t[-1] + dt * np.arange(1, round(GROUND_S / dt) + 1)
    n = len(t_ground)
    rotors = first.rotor_count
    ground = FlightLog(
        t=t_ground, position=np.tile([0.3, -0.2, z], (n, 1)), quat=np.tile([1.0, 0, 0, 0], (n, 1)),
        velocity=np.zeros((n, 3)), body_rate=np.zeros((n, 3)),
        accel=np.tile([0.0, 0.0, 9.81], (n, 1)), rotor_speed=np.zeros((n, rotors)),
        rotor_command=np.zeros((n, rotors)), vbat=np.full(n, vbat))
    later = dataclasses.replace(second, t=second.t + GROUND_S + dt)
    parts = (first, ground, later)
    return FlightLog(t=np.concatenate([p.t for p in parts]),
                     **{name: np.concatenate([getattr(p, name) for p in parts])
                        for name in ARRAYS})


def test_both_stretches_are_kept_as_segments(flown, cf):
    first, second, _ = flown
    log = _with_ground(first, second, z=0.0, vbat=4.0)
    checked, notes = check_logs([log], cf)
    joined = checked[0]
    assert len(joined.segments) == 1
    parts = joined.parts()
    assert [len(p.t) for p in parts] == [len(first.t), len(second.t)]
    assert len(joined.t) == len(first.t) + len(second.t)
    assert any("2 airborne stretches used" in n for n in notes)
    # convert --model keeps the longest only, and says so (unchanged)
    longest, said = check_log(log, cf)
    assert len(longest.t) == max(len(first.t), len(second.t))
    assert any("another airborne stretch" in n for n in said)


def test_states_are_each_stretch_prepared_alone(flown, cf):
    """The prepared flight's states are those of each stretch smoothed, trimmed and then
    joined (an independent path: flight_states on each stretch, not FlightLog.parts)."""
    first, second, _ = flown
    log = _with_ground(first, second, z=0.0, vbat=4.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        joined = check_logs([log], cf)[0][0]
        flight = prepare([joined], cf)[0]
    dt = float(np.median(np.diff(log.t)))
    alone = [flight_states(p, gravity=cf.gravity, dt=dt) for p in (first, second)]
    alone = [s.take(interior(s.t)) for s in alone]
    expect_t = np.concatenate([s.t for s in alone])
    second_t = alone[1].t + GROUND_S + dt
    expect_t = np.concatenate([alone[0].t, second_t])
    np.testing.assert_allclose(flight.states.t, expect_t, rtol=0, atol=1e-9)
    for name in ("specific_force", "body_accel", "rotor_speed", "velocity"):
        expect = np.concatenate([getattr(s, name) for s in alone])
        np.testing.assert_allclose(getattr(flight.states, name), expect, rtol=1e-9,
                                   atol=1e-9, err_msg=name)
    # the fit view: no sample closer than the ground span to both stretches
    gap = np.diff(flight.fit.t)
    assert np.count_nonzero(gap > 1.0) == 1


def test_the_verdict_does_not_see_the_ground_span(flown, cf):
    """Other numbers on the ground (another height and voltage): the same verdict, to the
    last digit; the mass offset (4 g on 37 g, +11 %) is read as a weight or the thrust that
    carries it (the three effects are confusable on so few references)."""
    first, second, reference = flown
    verdicts = []
    for z, vbat in ((0.0, 4.0), (-0.4, 3.1)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            joined = check_logs([_with_ground(first, second, z=z, vbat=vbat)], cf)[0][0]
        verdicts.append(judge_one(joined, reference))
    a, b = verdicts
    assert a.outcome == b.outcome and a.name == b.name and a.answer == b.answer
    assert a.probability == b.probability and dict(a.params) == dict(b.params)
    assert a.name in ("mass_offset", "thrust_factor", "thrust_curve"), a.answer


def test_gap_gathers_the_stretches_note():
    from quadsim.gap.__main__ import gather_notes

    said = gather_notes(["/a/f.csv: 2 airborne stretches used, t 0.00-2.50 s, 4.50-7.00 s "
                         "(5.00 of 7.00 s); cut: idle 2.51-4.49 s"])
    assert said == ["several take-offs or logging gaps: every airborne stretch used, each a "
                    "segment of its flight (the ground spans and gaps between them cut, "
                    "nothing fitted across them) on 1 log: f.csv 2 stretches (0.00-2.50 s, "
                    "4.50-7.00 s)"]


def test_a_logging_gap_in_flight_splits_the_stretch():
    """A time step of MIN_SPAN_S (0.5 s) or more inside an airborne stretch is a logging gap:
    the stretch is split there (each side a segment, nothing interpolated across it), a
    piece shorter than MIN_SPAN_S is dropped, both named in the cut list; a shorter gap
    (0.3 s) is bridged as before."""
    from quadsim.logs.flightlog import FlightLog
    from quadsim.logs.spans import airborne_spans, join_airborne

    def flying(t):
        n = len(t)
        return FlightLog(t=t, position=None, quat=None, body_rate=np.full((n, 3), 0.5),
                         accel=np.tile([0.0, 0.0, 9.81], (n, 1)),
                         rotor_speed=np.full((n, 4), 1500.0))

    step = 0.01
    a, b = np.arange(0, 3, step), 4.0 + np.arange(0, 3, step)      # a 1.01 s gap at 2.99 s
    spans = airborne_spans(flying(np.concatenate([a, b])))
    assert [(s.start, s.stop) for s in spans] == [(0, 300), (300, 600)]
    assert ("logging gap", pytest.approx(2.99), pytest.approx(4.0)) in spans[0].cut
    joined, note = join_airborne(flying(np.concatenate([a, b])))
    assert joined.segments == (300,) and "2 airborne stretches used" in note
    short = 4.0 + np.arange(0, 0.3, step)                            # 0.29 s after the gap
    spans = airborne_spans(flying(np.concatenate([a, short])))
    assert [(s.start, s.stop) for s in spans] == [(0, 300)]
    assert ("short", pytest.approx(4.0), pytest.approx(4.29)) in spans[0].cut
    bridged = np.concatenate([a, 3.29 + np.arange(0, 3, step)])     # a 0.3 s gap
    assert len(airborne_spans(flying(bridged))) == 1


def test_view_trajectory_differentiates_each_stretch_alone():
    """A joined log without velocity or gyro: the viewer's velocity is each stretch's own
    derivative (1 m/s and -2 m/s), never the jump between them."""
    t = np.concatenate([np.arange(0, 1, 0.01), 5 + np.arange(0, 1, 0.01)])
    x = np.concatenate([np.arange(100) * 0.01, 10 - 2 * np.arange(100) * 0.01])
    position = np.stack([x, np.zeros(200), np.ones(200)], 1)
    log = FlightLog(t=t, position=position, quat=np.tile([1.0, 0, 0, 0], (200, 1)),
                    segments=(100,))
    traj = log.to_trajectory()
    np.testing.assert_allclose(traj.velocity[:100, 0], 1.0, atol=1e-9)
    np.testing.assert_allclose(traj.velocity[100:, 0], -2.0, atol=1e-9)
    with pytest.raises(ValueError, match="segments"):
        FlightLog(t=t, position=position, quat=log.quat, segments=(0,))
