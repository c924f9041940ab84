"""The compiled MuJoCo path (quadsim.sim.compiled) against the step-by-step reference path.

Same physics, so the bound is 1e-9 m / 1e-9 rad over the whole flight (measured: identical to
the last bit on this machine). Also: batches with per-simulation effects, a controller, the
refusal/fallback of effects without a fast form, a diverging simulation named while the
others keep their results, the memory estimate, determinism. Skipped without numba (the
optional extra 'fast')."""

from __future__ import annotations

import numpy as np
import pytest

from quadsim.core.errors import InputError, SimulationError
from quadsim.effects import (
    EFFECTS,
    TESTBED_EXAMPLES,
    EffectBase,
    EffectSet,
    effect_set_from_specs,
)
from quadsim.sim import compiled as fast_mujoco
from quadsim.sim.controllers import GeometricController
from quadsim.sim.engines import initial_state, simulate
from quadsim.sim.paths import make_reference
from quadsim.vehicle.params import hover_speed, load_params

pytest.importorskip("numba", reason="numba is the optional extra 'fast'")

PARAMS = load_params("physical")
HOVER = hover_speed(PARAMS)
PERIOD = 0.01
TOL = 1e-9
# every example set of the library (each has a fast form: checked below); each effect once
FAST_EXAMPLES = list(TESTBED_EXAMPLES.values())
ALL = [specs[0] for specs in FAST_EXAMPLES]
ALL_EFFECTS = effect_set_from_specs(ALL)


def test_the_compiled_path_is_available_where_numba_is():
    assert fast_mujoco.available()


def test_every_library_effect_has_a_fast_form():
    assert {e.name for e in ALL_EFFECTS.effects} == set(EFFECTS)
    assert fast_mujoco.fast_form_problem([ALL_EFFECTS], [PARAMS]) is None
    for specs in FAST_EXAMPLES:
        assert fast_mujoco.fast_form_problem([effect_set_from_specs(list(specs))],
                                             [PARAMS]) is None, specs


def _series(batch: int, periods: int) -> np.ndarray:
    t = np.arange(periods) * PERIOD
    wobble = np.sin(2 * np.pi * np.outer(np.arange(1, batch + 1), t))[:, :, None]
    return HOVER * (1 + 0.02 * wobble * np.array([1.0, -0.5, 0.7, -1.0]))


def _start(batch: int) -> dict:
    def tile(v):
        return np.tile(v, (batch, 1))
    return initial_state(position=tile([0.0, 0.0, 0.3]), velocity=tile([3.0, -2.0, 0.5]),
                         euler=tile([0.02, -0.01, 0.2]), body_rate=tile([0.3, -0.2, 0.1]))


def _both(**kw):
    return [simulate(PARAMS, engine="mujoco", fast=fast, **kw) for fast in (True, False)]


def _assert_same(a, b):
    for name in ("position", "velocity", "quat", "body_rate", "rotor_speed", "rotor_command"):
        assert np.abs(getattr(a, name) - getattr(b, name)).max() <= TOL, name


@pytest.mark.parametrize("dynamics", [False, True])
def test_every_effect_matches_reference_open_loop(dynamics):
    # one simulation per effect (each example set) plus one with all of them at once; one
    # batch is all with rotor dynamics (motor_lag, battery_sag: alone and with the lag) or
    # all without
    sets = [effect_set_from_specs(list(s)) for s in FAST_EXAMPLES]
    sets = [s for s in sets if s.has_rotor_dynamics() == dynamics]
    sets.append(EffectSet(tuple(e for e in ALL_EFFECTS.effects
                                if EffectSet((e,)).has_rotor_dynamics() == dynamics)))
    fast, ref = _both(initial=_start(len(sets)), rotor_speed_series=_series(len(sets), 30),
                      duration=0.3, effects=sets)
    _assert_same(fast, ref)
    assert np.abs(fast.position[:, -1] - fast.position[0, -1]).max() > 1e-6  # effects act


def test_a_thrust_curves_curvature_about_its_centre_matches_reference():
    """The kernel expands ``l (W - c) + q (W - c)^2 + o`` about zero speed (encode); the
    reference path evaluates it about the centre: the same flight, and the curvature acts
    (against the same curve without it)."""
    curved = "thrust_curve:linear=-2e-4,quadratic=-2e-6,centre=450,offset=0.02"
    sets = [effect_set_from_specs([curved, "thrust_factor:change=-0.1"]),
            effect_set_from_specs([curved.replace("quadratic=-2e-6,", "")])]
    fast, ref = _both(initial=_start(2), rotor_speed_series=_series(2, 30), duration=0.3,
                      effects=sets)
    _assert_same(fast, ref)
    flat = simulate(PARAMS, engine="mujoco", fast=True, initial=_start(2), duration=0.3,
                    rotor_speed_series=_series(2, 30), effects=[sets[1]] * 2)
    assert np.abs(fast.position[0, -1] - flat.position[0, -1]).max() > 1e-6


def test_all_effects_with_motor_lag_and_controller_match_reference():
    kw = {"initial": _start(2), "duration": 0.3, "effects": ALL_EFFECTS}
    fast, ref = _both(rotor_speed_series=_series(2, 30), **kw)
    _assert_same(fast, ref)
    # a second run reuses the first one's (reset) MjData and compiled models: same bits
    again = simulate(PARAMS, engine="mujoco", fast=True, rotor_speed_series=_series(2, 30), **kw)
    assert np.array_equal(again.position, fast.position)
    assert np.array_equal(again.quat, fast.quat)
    reference = make_reference("figure8", speed=1.0)
    c1, c2 = (GeometricController(PARAMS, reference) for _ in range(2))
    kw.update(initial=c1.initial_state(), duration=0.5)
    a = simulate(PARAMS, controller=c1, fast=True, **kw)
    b = simulate(PARAMS, controller=c2, fast=False, **kw)
    _assert_same(a, b)
    assert np.abs(a.rotor_command - a.rotor_command[0, 0]).max() > 1.0   # it did steer


def test_body_drag_per_axis_matches_reference():
    """The per-axis body drag (``per_axis = 1``) in the compiled kernel and the reference
    path, flying obliquely through the air (3, -2, 0.5 m/s at the start): the same states to
    1e-9, and not those of the law on the air speed."""
    sets = [effect_set_from_specs([f"body_drag:cd_area=0.05,cd_area_vertical=0.08,"
                                   f"per_axis={k}"]) for k in (1.0, 0.0)]
    fast, ref = _both(initial=_start(2), rotor_speed_series=_series(2, 30), duration=0.3,
                      effects=sets)
    _assert_same(fast, ref)
    assert np.abs(fast.velocity[0, -1] - fast.velocity[1, -1]).max() > 1e-4


def test_no_effects_is_bit_identical_and_deterministic():
    fast, ref = _both(initial=_start(3), rotor_speed_series=_series(3, 20), duration=0.2)
    assert np.array_equal(fast.position, ref.position)
    again = simulate(PARAMS, initial=_start(3), rotor_speed_series=_series(3, 20), duration=0.2)
    assert np.array_equal(fast.position, again.position)


class _Stateful(EffectBase):
    name = "not_in_library"


def test_effect_without_fast_form_falls_back_or_is_refused_by_name():
    effects = EffectSet((_Stateful(),))
    assert "not_in_library" in fast_mujoco.fast_form_problem([effects], [PARAMS])
    with pytest.raises(InputError, match="fast path unavailable: effect 'not_in_library'"):
        simulate(PARAMS, duration=0.02, effects=effects, fast=True)
    simulate(PARAMS, duration=0.02, effects=effects)        # default: the reference path


def test_one_diverging_simulation_is_named_and_others_kept():
    start = initial_state(position=[[0, 0, 1], [0, 0, 1]], velocity=[[0, 0, 0], [2e6, 0, 0]])
    with pytest.raises(SimulationError, match=r"simulation\(s\) \[1\] diverged") as info:
        simulate(PARAMS, initial=start, duration=0.05, fast=True)
    partial = info.value.partial
    good = simulate(PARAMS, initial=initial_state(position=(0, 0, 1)), duration=0.05)
    assert np.array_equal(partial["position"][0], good.position)
    assert np.isnan(partial["position"][1, -1]).all()
    assert info.value.diverged == [1]


def test_batch_too_large_for_memory_is_refused_before_allocating(monkeypatch):
    from quadsim.sim import mujoco_engine

    model = mujoco_engine.compile_model(PARAMS, 1e-3)
    per_sim = mujoco_engine.check_memory(model, 1, 10, 4)
    assert per_sim > 1000                     # an MjData is at least kilobytes
    monkeypatch.setattr(mujoco_engine, "MEMORY_FRACTION", per_sim * 1e-12)
    monkeypatch.setattr(mujoco_engine, "_make_batch", lambda *a: pytest.fail("allocated"))
    monkeypatch.setattr(mujoco_engine, "body_arrays", lambda *a: pytest.fail("allocated"))
    with pytest.raises(InputError, match="batch of 4 simulations needs about"):
        simulate([PARAMS] * 4, duration=0.01)


def test_analytic_compiled_rhs_matches_numpy_rhs():
    # every effect at once (with the payload's internal state) and motor_lag alone (no
    # state: padded), a batch of two with different commands
    lag_only = effect_set_from_specs(list(TESTBED_EXAMPLES["motor_lag"]))
    kw = {"engine": "analytic", "initial": _start(2), "rotor_speed_series": _series(2, 20),
          "duration": 0.2, "effects": [ALL_EFFECTS, lag_only]}
    fast = simulate(PARAMS, fast=None, **kw)
    ref = simulate(PARAMS, fast=False, **kw)
    _assert_same(fast, ref)
    mujoco = simulate(PARAMS, engine="mujoco", **{k: v for k, v in kw.items() if k != "engine"})
    assert np.abs(mujoco.position - fast.position).max() < 1e-4     # the engines agree
