"""The references' envelope (quadsim.gap.reference) and flights flown outside it: closed-form
checks of the trend and of the reference model moved to a flight's place, and generated
flights flown 1.6x faster than their references (no effect: no gap; +20 % mass: named)."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.effects import make_effect
from quadsim.gap.calibrate import Reference, calibrate
from quadsim.gap.diagnose import judge_one, prepare
from quadsim.gap.fitting import Candidate
from quadsim.gap.reference import Envelope, coordinates, fit_trend, local_reference, position
from quadsim.vehicle.params import load_params

from _helpers import shared_effects  # noqa: E402


def _states(speed: float, rate: float, thrust: float, n: int = 400):
    """States whose envelope coordinates are exactly (speed, rate, thrust) (RMS values)."""
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    velocity = np.zeros((n, 3))
    velocity[:, 0] = speed
    body_rate = np.zeros((n, 3))
    body_rate[:, 2] = rate
    force = np.zeros((n, 3))
    force[:, 2] = 9.81 + thrust * sign
    return SimpleNamespace(velocity=velocity, body_rate=body_rate, specific_force=force)


def _reference(coords, slope, lof_slope, names=4):
    """A one-parameter reference (the motor map's gain) whose references' own values drift
    along their axis by ``slope`` per unit place, their log mean squares by ``lof_slope``."""
    cf = load_params("crazyflie21")
    cand = Candidate("reference", (("speed_gain", {}, ("gain",)),))
    channels = 10
    trend_coords = np.log(coords)
    axis = np.linalg.svd(trend_coords - trend_coords.mean(0), full_matrices=False)[2][0]
    axis = axis if axis[0] > 0 else -axis
    u = trend_coords @ axis
    values = (slope * (u - u.mean()))[:, None]
    log_ms = np.outer(u - u.mean(), lof_slope * np.ones(channels))
    trend = fit_trend(trend_coords, values, np.full_like(values, 1e-4), np.array([True]),
                      log_ms)
    ref = Reference(cf, True, cand, np.zeros(1), np.full(1, 1e-5), np.zeros(1),
                    np.ones(channels), np.ones(channels), np.zeros(channels), 0.2, 30, {},
                    [f"r{k}" for k in range(names)], {"speed_gain.gain": True})
    ref.envelope = Envelope(trend_coords, trend)
    return ref, trend, u


COORDS = np.array([[0.6, 1.2, 0.3], [0.7, 1.4, 0.35], [0.8, 1.6, 0.4], [0.9, 1.8, 0.45]])


def test_coordinates_are_the_logs_of_the_rms_values():
    assert coordinates(_states(0.9, 2.0, 0.5)) == pytest.approx(np.log([0.9, 2.0, 0.5]),
                                                                abs=1e-12)


def test_trend_recovers_an_exact_linear_drift():
    """Values and log mean squares exactly linear in the place: slopes recovered to
    round-off, no residual spread."""
    _, trend, _ = _reference(COORDS, slope=0.004, lof_slope=0.7)
    assert trend.slope[0] == pytest.approx(0.004, rel=1e-9)
    assert np.allclose(trend.lof_slope, 0.7, rtol=1e-9)
    assert trend.lof_sd < 1e-9


def test_a_flight_16x_faster_is_outside_by_log_16_and_the_model_widens_by_the_trend():
    ref, trend, u = _reference(COORDS, slope=0.004, lof_slope=0.7)
    fast = _states(*(1.6 * COORDS[-1]))
    pos = position(fast, ref.envelope)
    assert pos.distance == pytest.approx(np.log(1.6), abs=1e-9)
    assert "1.60x the largest reference's" in pos.text
    local = local_reference(ref, pos)
    edge = pos.u - u.max()
    assert edge == pytest.approx(np.log(1.6) * np.sum(trend.axis), rel=1e-9)
    # the shared value follows the trend to the flight's place (the regression's prediction,
    # its variance added); beyond the outermost reference its spread grows by what the trend
    # moves it by there (slope and slope uncertainty)
    lead = pos.u - trend.u_w[0]
    assert local.theta[0] == pytest.approx(ref.theta[0] + 0.004 * lead, rel=1e-9)
    assert local.scatter[0] == pytest.approx(
        np.sqrt(trend.slope_var[0] * lead ** 2 + (0.004 ** 2 + trend.slope_var[0]) * edge ** 2),
        rel=1e-9)
    # the residual expected exp(0.7 edge) larger, carried as noise (sigma), so the
    # lack-of-fit mean is unchanged
    assert np.allclose(local.sigma, np.exp(0.7 * edge / 2), rtol=1e-12)
    assert np.allclose(local.lof_mean, 0.0, atol=1e-12)
    assert local.scatter[0] > 0
    # the lack-of-fit spread per channel: the references' own, and the trend's move there
    # (it may bend beyond them); the regression's prediction term is 0 (an exact line)
    np.testing.assert_allclose(local.lof_sd, np.sqrt(ref.lof_sd ** 2 + (0.7 * edge) ** 2),
                               rtol=1e-12)


def test_inside_the_envelope_the_noise_model_is_the_references():
    ref, _, u = _reference(COORDS, slope=0.004, lof_slope=0.7)
    pos = position(_states(*COORDS[1:3].mean(0)), ref.envelope)
    assert pos.distance == 0.0 and "inside" in pos.text
    local = local_reference(ref, pos)
    assert np.array_equal(local.sigma, ref.sigma)
    assert np.array_equal(local.lof_mean, ref.lof_mean)
    assert np.all(local.lof_sd == ref.lof_sd)
    # the shared value is the trend's at the flight's place, inside the envelope too
    assert local.theta[0] == pytest.approx(0.004 * (pos.u - np.mean(u)), abs=1e-12)


def test_references_that_do_not_spread_give_no_trend():
    _, trend, _ = _reference(np.repeat(COORDS[:1], 4, axis=0) * [[1.0], [1.001], [1.002],
                                                                       [1.003]], 0.004, 0.7)
    assert trend is None
    pos = position(_states(*(1.6 * COORDS[0])), Envelope(np.log(COORDS[:1]), None))
    assert pos.distance > 0 and "do not spread enough" in pos.text


def test_the_model_at_a_flight_stays_a_rigid_body():
    """A flat frame (the Crazyflie model: Izz = 0.74 (Ixx + Iyy)) whose references' yaw
    inertia error trends by +0.5 per unit place: at a flight 1.6x beyond them the trend asks
    for more than the triangle inequality allows (Izz <= Ixx + Iyy, i.e. zz <= 0.344 with
    xx = yy = 0). The reference model there stops on the wall (to 1e-6) and its spread takes
    up the part of the move left out."""
    from quadsim.effects.base import EffectSet

    cf = load_params("crazyflie21")
    cand = Candidate("reference", (("inertia_error", {}, ("xx", "yy", "zz")),))
    trend_coords = np.log(COORDS)
    axis = np.linalg.svd(trend_coords - trend_coords.mean(0), full_matrices=False)[2][0]
    u = trend_coords @ (axis if axis[0] > 0 else -axis)
    values = np.zeros((len(u), 3))
    values[:, 2] = 0.5 * (u - u.mean())
    trend = fit_trend(trend_coords, values, np.full_like(values, 1e-4),
                      np.array([True, True, True]), np.zeros((len(u), 10)))
    ref = Reference(cf, True, cand, np.zeros(3), np.full(3, 1e-5), np.zeros(3),
                    np.ones(10), np.ones(10), np.zeros(10), 0.2, 30, {},
                    [f"r{k}" for k in range(4)], {})
    ref.envelope = Envelope(trend_coords, trend)
    pos = position(_states(*(1.6 * COORDS[-1])), ref.envelope)
    wanted = 0.5 * (pos.u - trend.u_w[2])
    inertia = np.diag(cf.inertia)
    wall = (inertia[0] + inertia[1]) / inertia[2] - 1.0
    assert wanted > wall + 0.2                          # the trend's value: no rigid body
    local = local_reference(ref, pos)                   # no ModelError
    assert local.theta[2] == pytest.approx(wall, abs=1e-6)
    assert local.theta[2] <= wall + 1e-6               # (check_physical's own tolerance)
    EffectSet(tuple(local.effects())).apply_to_params(cf)     # physical
    assert local.scatter[2] >= wanted - wall


def _inertia_reference(values, info=None):
    """A Crazyflie reference with shared inertia errors (xx, yy, zz) whose references'
    own values are ``values`` (4, 3) at the places of COORDS (standard errors 1e-3) and
    whose inverse information per sample is ``info`` (4, 3)."""
    cf = load_params("crazyflie21")
    cand = Candidate("reference", (("inertia_error", {}, ("xx", "yy", "zz")),))
    trend_coords = np.log(COORDS)
    trend = fit_trend(trend_coords, values, np.full_like(values, 1e-3),
                      np.array([True, True, True]), np.zeros((len(values), 10)), info)
    mean = values.mean(axis=0)
    ref = Reference(cf, True, cand, mean, np.full(3, 1e-5), np.zeros(3),
                    np.ones(10), np.ones(10), np.zeros(10), 0.2, 30, {},
                    [f"r{k}" for k in range(4)], {})
    ref.envelope = Envelope(trend_coords, trend)
    return ref, trend


def test_a_bias_that_follows_the_inverse_information_is_carried_by_it():
    """Roll inertia errors that are exactly 0.02 q (q: the inverse information per sample,
    spread over an e-fold and a half, and not a line in the place): the inverse-information
    line wins (weight 1 to 1e-6), and at a flight with 3x the largest reference's q the
    reference model's roll value is that line's, 0.02 q, its spread at least the line's move
    beyond the outermost reference. A parameter whose information spreads less than an
    e-fold keeps the place's line alone."""
    q = np.array([[0.5, 1.0, 1.0], [0.8, 1.01, 1.0], [1.5, 1.02, 1.0], [2.4, 1.03, 1.0]])
    values = np.zeros((4, 3))
    values[:, 0] = 0.02 * q[:, 0]
    ref, trend = _inertia_reference(values, q)
    assert trend.q_weight[0] == pytest.approx(1.0, abs=1e-6)
    assert trend.q_weight[1] == 0.0 and trend.q_weight[2] == 0.0
    flight = np.array([3 * 2.4, 1.0, 1.0])
    pos = position(_states(*COORDS[-1]), ref.envelope, flight)
    local = local_reference(ref, pos)
    assert local.theta[0] == pytest.approx(0.02 * flight[0], rel=1e-6)
    assert local.scatter[0] >= 0.02 * (flight[0] - 2.4)
    # the JSON names the parameter that has the line, with its weight
    from quadsim.gap.reference import envelope_summary
    lines = envelope_summary(ref.envelope, ref.candidate.parameter_names)["information_line"]
    assert list(lines) == ["inertia_error.xx"]
    assert lines["inertia_error.xx"] == pytest.approx(1.0, abs=1e-6)
    # without the flight's information the place's line is used
    plain = local_reference(ref, position(_states(*COORDS[-1]), ref.envelope))
    assert plain.theta[0] == pytest.approx(values[-1, 0], abs=0.02)


def test_the_wall_takes_back_the_least_certain_move_first():
    """Roll and pitch errors +30 % measured by the inverse-information line (certain), yaw
    error +150 % by it too but with scatter about its line: the yaw value alone goes back to the
    triangle inequality's wall (Izz = Ixx + Iyy), roll and pitch keep their +30 %."""
    from quadsim.effects.base import EffectSet

    q = np.array([[0.5] * 3, [0.8] * 3, [1.5] * 3, [2.4] * 3])
    values = np.column_stack([0.1 * q[:, 0], 0.1 * q[:, 0], 0.5 * q[:, 0]])
    values[:, 2] += np.array([0.0, 0.1, -0.1, 0.0])          # a yaw line with scatter
    ref, _trend = _inertia_reference(values, q)
    flight = np.full(3, 3.0)
    pos = position(_states(*COORDS[-1]), ref.envelope, flight)
    local = local_reference(ref, pos)
    cf = ref.params
    inertia = np.diag(cf.inertia)
    wall = (inertia[0] * (1 + local.theta[0]) + inertia[1] * (1 + local.theta[1])) \
        / inertia[2] - 1.0
    assert local.theta[0] == pytest.approx(0.3, abs=1e-6)
    assert local.theta[1] == pytest.approx(0.3, abs=1e-6)
    assert 0.5 * 3.0 > wall + 0.5                     # the line's yaw value: no rigid body
    assert local.theta[2] == pytest.approx(wall, abs=1e-6)
    assert local.scatter[2] >= 0.5 * 3.0 - wall - 0.05   # the move left out, in its spread
    EffectSet(tuple(local.effects())).apply_to_params(cf)     # physical


#: one xdist worker runs this module's tests (pytest-xdist --dist loadgroup): its module-scoped
#: fixtures are built once, not once per worker
pytestmark = pytest.mark.xdist_group("test_envelope")


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def slow_reference(cf):
    """Four nominal generated flights at path speeds 0.5-0.65 (shared motor lag and rotor
    drag)."""
    logs = [synthetic_flight(cf, shared_effects(), duration=5.0, seed=s,
                             speed=0.5 + 0.05 * s) for s in range(4)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        return calibrate(prepare(logs, cf), cf)


#: 1.6x the references' mean path speed (0.575)
FAST = 0.92


def test_a_nominal_flight_16x_faster_is_no_significant_gap(cf, slow_reference):
    log = synthetic_flight(cf, shared_effects(), duration=5.0, seed=20, speed=FAST)
    entry = judge_one(log, slow_reference)
    assert entry["outcome"] == "no_significant_gap", entry["answer"]
    assert entry["envelope"]["outside"] and entry["envelope"]["distance"] > np.log(1.3)
    assert "outside the reference flights' envelope" in entry["answer"]


def test_a_real_effect_on_a_flight_16x_faster_is_still_named(cf, slow_reference):
    mass = 0.2 * cf.mass
    log = synthetic_flight(cf, shared_effects() + [make_effect("mass_offset", mass=mass)],
                           duration=5.0, seed=21, speed=FAST)
    entry = judge_one(log, slow_reference)
    assert entry["verdict"] == "mass_offset" and entry["probability"] > 0.9, entry["answer"]
    assert entry["params"]["mass_offset.mass"] == pytest.approx(mass, rel=0.05)
