"""Fixed-step RK4 rollouts (benchmarks.rollout) against the adaptive analytic engine, an
independent implementation of the rate-held model, and the blade-flapping closed form."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import nanodrone as bench
from benchmarks.rollout import rollout
from quadsim.core.errors import InputError
from quadsim.effects import effect_set_from_specs, make_effect
from quadsim.effects.base import EffectContext
from quadsim.effects.blade_flapping import flapping_moment
from quadsim.sim.engines import simulate
from quadsim.vehicle.params import hover_speed, load_params

PARAMS = load_params("crazyflie21")
RNG = np.random.default_rng(7)
B = 6
START = {"position": RNG.normal(size=(B, 3)), "velocity": RNG.normal(size=(B, 3)),
         "quat": np.tile([1.0, 0.0, 0.0, 0.0], (B, 1)), "body_rate": RNG.normal(size=(B, 3))}
SERIES = hover_speed(PARAMS) * (1 + 0.05 * RNG.normal(size=(B, 50, 4)))


@pytest.mark.parametrize("specs", [[], ["rotor_drag:coefficient=2.7e-6",
                                        "blade_flapping:coefficient=3e-8"]])
def test_rollout_matches_the_adaptive_analytic_engine(specs):
    """0.5 s of a tumbling Crazyflie (body rates ~1 rad/s, 5 % speed noise): RK4 at one step
    per 10 ms period within 1e-6 m / 1e-5 rad/s of DOP853 at rtol 1e-11."""
    effects = effect_set_from_specs(specs)
    fast = rollout(PARAMS, initial=START, rotor_speed_series=SERIES, control_period=0.01,
                   effects=effects, substeps=1)
    ref = simulate(PARAMS, engine="analytic", initial=START, rotor_speed_series=SERIES,
                   duration=0.5, control_period=0.01, effects=effects)
    assert np.abs(fast["position"] - ref.position).max() < 1e-6
    assert np.abs(fast["body_rate"] - ref.body_rate).max() < 1e-5
    numpy_path = rollout(PARAMS, initial=START, rotor_speed_series=SERIES, control_period=0.01,
                         effects=effects, substeps=1, fast=False)
    assert np.abs(numpy_path["position"] - fast["position"]).max() < 1e-9


def test_rate_held_rollout_is_the_benchmarks_physics_model():
    """With the authors' mass and thrust factor, zero drag factor and the rate held, quadsim's
    rollout and the independent transcription of their model agree (their RK4 renormalises
    the quaternion at every stage, ours after each step: 1e-9 m)."""
    from dataclasses import replace

    p = replace(PARAMS, mass=bench.MASS, thrust_factor=bench.KT, drag_factor=0.0,
                gravity=bench.GRAVITY)
    windows = bench.Windows(START["position"], START["velocity"], START["quat"],
                            START["body_rate"], SERIES, {}, np.zeros(B, int), ("x",))
    theirs = bench.physics_prediction(windows)
    ours = rollout(p, initial=START, rotor_speed_series=SERIES, control_period=0.01,
                   substeps=1, hold_body_rate=True)
    assert np.abs(ours["position"][:, 1:] - theirs["p"]).max() < 1e-9
    np.testing.assert_array_equal(ours["body_rate"][:, -1], START["body_rate"])


def test_rollout_refuses_bad_series():
    with pytest.raises(InputError, match="rotor_speed_series"):
        rollout(PARAMS, initial=START, rotor_speed_series=SERIES[:, :, :3], control_period=0.01)
    bad = SERIES.copy()
    bad[0, 3, 1] = np.nan
    with pytest.raises(InputError, match="NaN"):
        rollout(PARAMS, initial=START, rotor_speed_series=bad, control_period=0.01)


def test_blade_flapping_moment_closed_form():
    """Docstring example: 1 m/s forward, four rotors at 2250 rad/s, k = 3e-8 kg m/rad:
    tau = k * 9000 * (v_y, -v_x, 0) = (0, -2.7e-4, 0) N m; vertical flow gives none."""
    axes = np.tile([0.0, 0.0, 1.0], (4, 1))
    tau = flapping_moment(np.array([[1.0, 0.0, 0.3]]), np.full((1, 4), 2250.0), axes, 3e-8)
    np.testing.assert_allclose(tau, [[0.0, -2.7e-4, 0.0]], atol=1e-18)
    effect = make_effect("blade_flapping", coefficient=3e-8)
    ctx = EffectContext(t=np.zeros(1), position=np.zeros((1, 3)),
                        velocity=np.array([[0.0, 2.0, 0.0]]), quat=np.array([[1.0, 0, 0, 0]]),
                        body_rate=np.zeros((1, 3)), air_velocity=np.array([[0.0, 2.0, 0.0]]),
                        rotor_speed=np.full((1, 4), 2250.0), rotor_accel=np.zeros((1, 4)),
                        params=PARAMS, vbat=None)
    np.testing.assert_allclose(effect.loads(ctx).torque_body, [[5.4e-4, 0.0, 0.0]], atol=1e-18)
