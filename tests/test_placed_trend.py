"""The placed reference model beyond references whose trend does not reach the flight
(issue 47; quadsim.gap.reference.Trend.measured, local_reference): the shared values are
read on the trend's line at the outermost reference, not extrapolated, where the
references do not measure how their model's lack of fit grows along their axis or where
the flight lies beyond their reach; closed forms, and generated references flown alike
with a payload flown beyond them, its mass read right within its interval."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from quadsim.gap.calibrate import Reference
from quadsim.gap.fitting import Candidate
from quadsim.gap.reference import (
    PROPORTIONAL_SLOPE,
    REACH_Z,
    Envelope,
    Position,
    fit_trend,
    local_reference,
    reach_of,
    slope_errors,
)
from quadsim.vehicle.params import load_params

from _helpers import generated_flight

C = 6           # residual channels of the stub references
#: the references' log mean squares scatter by 0.1 (log units) with no relation to their place
SCATTER = 0.1 * np.array([[1, -1, 0.5, 0, 1, -1], [-1, 0.5, 1, 1, 0, 0.5],
                          [0.5, 1, -1, -1, -0.5, 0], [-0.5, -0.5, -0.5, 0.5, 0.5, 1],
                          [0.5, 0, 0, -0.5, -1, -0.5]])
#: their own values of the motor map's gain: a noise slope, no trend
VALUES = np.array([[2e-3], [-1e-3], [3e-3], [-2e-3], [1e-3]])
SE = np.full((5, 1), 2e-3)


def _reference(coords, excite=None):
    """A one-parameter reference (the motor map's gain, pooled value 0, no scatter) on five
    references at ``coords`` (n, 3, log units) with VALUES, SCATTER and, where given, their
    excitations ``excite`` (n, C)."""
    trend = fit_trend(coords, VALUES, SE, np.array([True]), SCATTER)
    ref = Reference(load_params("crazyflie21"), True,
                    Candidate("reference", (("speed_gain", {}, ("gain",)),)),
                    np.zeros(1), np.full(1, 1e-5), np.zeros(1), np.ones(C), np.ones(C),
                    SCATTER.mean(axis=0), 0.1, 4 * C, {}, [f"r{k}" for k in range(5)],
                    {"speed_gain.gain": True})
    ref.envelope = Envelope(coords, trend, excite=excite)
    ref.log_ms = SCATTER
    return ref, trend


def _place(ref, coords, excite=None):
    coords = np.asarray(coords, float)
    env = ref.envelope
    excess = np.maximum(np.maximum(coords - env.high, env.low - coords), 0.0)
    return Position(coords, float(excess.max()), "speed", float(coords @ env.trend.axis), "",
                    None, excite)


#: five references flown alike: places within 5 % along one direction
ALIKE = np.log(np.outer([1.0, 1.0125, 1.025, 1.0375, 1.05], [1.0, 1.0, 1.0]))
#: five references spread by a factor 3 along the same direction
SPREAD = np.log(np.outer([1.0, 1.3, 1.7, 2.2, 3.0], [1.0, 1.0, 1.0]))


def test_the_growth_error_is_the_pooled_slope_error_on_the_place():
    """growth_se: an independent implementation (slope_errors with the place as the one
    regressor; numpy's polyfit per channel for the residual)."""
    _, trend = _reference(SPREAD)
    u = SPREAD @ trend.axis
    assert trend.growth_se == pytest.approx(slope_errors(u, SCATTER)[0], rel=1e-10)
    rss = sum(float(np.sum((SCATTER[:, c] - np.polyval(np.polyfit(u, SCATTER[:, c], 1), u))
                           ** 2)) for c in range(C))
    want = np.sqrt(rss / (C * (len(u) - 2))) / np.sqrt(np.sum((u - u.mean()) ** 2))
    assert trend.growth_se == pytest.approx(want, rel=1e-10)
    # spread by a factor 3: the growth is measured (1.96 se = 0.11 within 2); flown alike
    # (places spanning 5 %, as one speed group of the real Crazyflie references): the same
    # scatter over a 22x narrower span, 1.96 se = 2.5 above 2, not measured
    assert trend.measured and REACH_Z * trend.growth_se == pytest.approx(0.111, abs=1e-3)
    _, alike = _reference(ALIKE)
    u = ALIKE @ alike.axis
    assert alike.growth_se == pytest.approx(slope_errors(u, SCATTER)[0], rel=1e-10)
    assert not alike.measured and REACH_Z * alike.growth_se > PROPORTIONAL_SLOPE


def test_references_flown_alike_hold_the_shared_values_at_the_outermost_reference():
    """A flight 1.6x beyond references flown alike: the gain is the line's value at the
    outermost reference, b (u_max - u_w), its spread the line's there, sqrt(var(b))
    |u_max - u_w| (not the extrapolation's, here 29x that: a noise slope measured over a
    span of places of 0.085 carried 0.81 beyond it)."""
    ref, trend = _reference(ALIKE)
    pos = _place(ref, ALIKE[-1] + np.log(1.6))
    assert pos.u > trend.u_high
    local = local_reference(ref, pos)
    at = trend.u_high - trend.u_w[0]
    assert local.theta[0] == pytest.approx(trend.slope[0] * at, rel=1e-9, abs=1e-15)
    assert local.scatter[0] == pytest.approx(np.sqrt(trend.slope_var[0]) * abs(at), rel=1e-9)
    lead, edge = pos.u - trend.u_w[0], pos.u - trend.u_high
    extrapolated = np.sqrt(trend.slope_var[0] * lead ** 2
                           + (trend.slope[0] ** 2 + trend.slope_var[0]) * edge ** 2)
    assert extrapolated == pytest.approx(29.2 * local.scatter[0], rel=0.01)
    # the answer says so
    from types import SimpleNamespace

    from quadsim.gap.reference import position
    speed, rate, thrust = np.exp(ALIKE[-1] + np.log(1.6))
    states = SimpleNamespace(velocity=np.tile([speed, 0.0, 0.0], (400, 1)),
                             body_rate=np.tile([0.0, 0.0, rate], (400, 1)),
                             specific_force=np.column_stack(
                                 [np.zeros((400, 2)), 9.81 + thrust * np.resize([1, -1], 400)]))
    assert position(states, ref.envelope).text.endswith(
        "the reference model keeps their outermost values there, its noise widened")
    # inside their range the line is read where the flight lies, as before
    inside = _place(ref, ALIKE[2])
    assert local_reference(ref, inside).theta[0] == pytest.approx(
        trend.slope[0] * (inside.u - trend.u_w[0]), rel=1e-9, abs=1e-15)


def test_references_that_measure_their_growth_extrapolate_the_shared_values():
    """The same values on references spread by a factor 3: the trend is measured and a
    flight 1.6x beyond them gets the line's extrapolation and its spread there."""
    ref, trend = _reference(SPREAD)
    pos = _place(ref, SPREAD[-1] + np.log(1.6))
    local = local_reference(ref, pos)
    lead, edge = pos.u - trend.u_w[0], pos.u - trend.u_high
    assert edge > 0.5
    assert local.theta[0] == pytest.approx(trend.slope[0] * lead, rel=1e-9)
    assert local.scatter[0] == pytest.approx(
        np.sqrt(trend.slope_var[0] * lead ** 2
                + (trend.slope[0] ** 2 + trend.slope_var[0]) * edge ** 2), rel=1e-9)


def test_a_flight_beyond_the_reach_holds_the_shared_values():
    """References spread by a factor 3 in speed and body rate but flown with one thrust
    variation: their growth along their axis is measured, along the thrust coordinate not.
    A flight beyond them in speed and rate, 3x their thrust variation and driving a channel
    3x harder, is beyond their reach (reach_of): the gain is held at the outermost
    reference's; without excitations (no reach measured) the same flight extrapolates."""
    coords = SPREAD.copy()
    coords[:, 2] = 0.0
    excite = np.zeros((5, C))
    ref, trend = _reference(coords, excite)
    assert trend.measured
    flight = np.array([SPREAD[-1, 0] + 0.3, SPREAD[-1, 1] + 0.3, np.log(3.0)])
    pos = _place(ref, flight, np.log(np.array([3.0, 1, 1, 1, 1, 1])))
    assert reach_of(ref, pos) is not None and pos.u > trend.u_high
    local = local_reference(ref, pos)
    at = trend.u_high - trend.u_w[0]
    assert local.reach is not None
    assert local.theta[0] == pytest.approx(trend.slope[0] * at, rel=1e-9, abs=1e-15)
    assert local.scatter[0] == pytest.approx(np.sqrt(trend.slope_var[0]) * abs(at), rel=1e-9)
    plain, _ = _reference(coords)
    free = local_reference(plain, _place(plain, flight))
    assert free.reach is None
    assert free.theta[0] == pytest.approx(trend.slope[0] * (pos.u - trend.u_w[0]), rel=1e-9)


def test_a_generated_payload_flown_beyond_references_flown_alike_is_read_right():
    """Generated closed-loop flights (quadsim.logs.generate, MuJoCo, sensor noise): five
    references flown alike (figure-8 at 1.00-1.12 m/s, 4 s: their places span 0.42, their
    lack of fit's growth along the thrust variation not measured), then +7.4 g fixed to the
    frame flown with sharp stops at 1.5 m/s, 7x their thrust variation. Main 7797bf9
    extrapolated the references' trend to it and freed the thrust per Omega^2 with its
    variance: ``no_significant_gap`` 56 %, the mass +7.6 ± 9.7 g. Held at the outermost
    reference: the payload named at 0.93, its total +7.4 ± 2.4 g, holding the truth."""
    from quadsim.effects import make_effect
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare

    cf = load_params("crazyflie21")

    def fly(effects, seed, path, speed):
        return generated_flight(cf, effects, seed, path, speed)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = calibrate(prepare([fly([], s, "figure8", 1.0 + 0.03 * s) for s in range(5)],
                                cf), cf)
        v = judge_one(fly([make_effect("mass_offset", mass=0.0074)], 40, "steps", 1.5), ref)
    assert v.name == "cable_payload+mass_offset" and v.probability > 0.9, v.answer
    assert abs(v.total["mass"] - 7.4e-3) <= v.total["ci"], v.total
    assert v.total["mass"] == pytest.approx(7.4e-3, abs=1e-3)
    assert v.total["ci"] < 4e-3
