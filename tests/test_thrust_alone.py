"""One rotor's thrust change whose drag torque does not follow (``thrust_mismatch``'s
``torque_share``): its loads against the closed form, both engines alike, the speed a command
gives, the bit-for-bit default, and the diagnosis' reading of it (its facts)."""

from __future__ import annotations

import types

import numpy as np
import pytest

from quadsim.effects import EFFECTS, EffectContext, effect_set_from_specs, make_effect
from quadsim.gap.explanations import _reading, prior_spreads
from quadsim.gap.judge import FORM_TOLD, form_words
from quadsim.sim import engines
from quadsim.sim.compiled import fast_form_problem
from quadsim.vehicle.params import hover_speed, load_params
from quadsim.vehicle.rotors import allocation_matrix

PARAMS = load_params("physical")
SPEEDS = np.array([[900.0, 950.0, 1000.0, 1050.0], [700.0, 720.0, 740.0, 760.0]])


def _ctx(params, speed):
    n = len(speed)
    zeros = np.zeros((n, 3))
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return EffectContext(np.zeros(n), zeros, zeros, quat, zeros, zeros, speed,
                         np.zeros_like(speed), params)


def _wrench(params, loads, speed):
    """Body wrench (N, 6) of the rotors plus the effect's body torque: the closed form's
    counterpart, through the allocation matrix (independent of the effect's arithmetic)."""
    wrench = (np.square(speed) * loads.thrust_scale) @ allocation_matrix(params).T
    wrench[:, 3:] += loads.torque_body
    return wrench


@pytest.mark.parametrize("share", [0.0, 0.4, 1.0, 1.5])
def test_loads_are_the_closed_form(share):
    """Rotor 3 at e = -0.1: force and roll/pitch torque those of (1 + e) b Omega_3^2 along its
    axis, yaw torque that of (1 + s e) d Omega_3^2 -- against the nominal allocation with
    rotor 3's two factors written out by hand."""
    effect = make_effect("thrust_mismatch", rotor_3=-0.1, torque_share=share)
    got = _wrench(PARAMS, effect.loads(_ctx(PARAMS, SPEEDS)), SPEEDS)
    b, d = PARAMS.thrust_factor, PARAMS.drag_factor
    axes, arms = PARAMS.rotor_axes, PARAMS.rotor_positions - PARAMS.com
    thrust = np.ones(4)
    torque = np.ones(4)
    thrust[2], torque[2] = 0.9, 1.0 - 0.1 * share
    w2 = np.square(SPEEDS)
    force = (w2 * thrust * b) @ axes
    moment = np.einsum("nr,rk->nk", w2 * thrust * b, np.cross(arms, axes)) \
        - (w2 * torque * d * PARAMS.rotor_spins) @ axes
    np.testing.assert_allclose(got[:, :3], force, rtol=1e-12)
    np.testing.assert_allclose(got[:, 3:], moment, rtol=1e-12, atol=1e-15)


def test_the_default_share_is_the_old_effect_bit_for_bit():
    """torque_share 1 (the default): the loads are the thrust scale alone, the body torque the
    shared neutral array, the speed factor (1 + e)^-alpha -- the same numbers as before."""
    effect = make_effect("thrust_mismatch", rotor_2=-0.07, alpha=0.2)
    loads = effect.loads(_ctx(PARAMS, SPEEDS))
    assert loads.is_neutral("torque_body")
    dev = np.array([0.0, -0.07, 0.0, 0.0])
    assert np.array_equal(loads.thrust_scale, np.broadcast_to(1.0 + dev, (2, 4)))
    assert np.array_equal(effect.rotor_speed_factor(4), (1.0 + dev) ** -0.2)
    assert fast_form_problem([effect_set_from_specs(["thrust_mismatch:rotor_2=-0.07"])],
                             [PARAMS]) in (None, "numba is not installed (pip install "
                                                 "quadsim[fast])")


def test_the_speed_per_command_follows_the_drag_torque():
    """The motor's load is the drag torque: thrust alone leaves the speed a command gives
    (factor exactly 1: None), a share of 0.5 gives (1 + 0.5 e)^-alpha."""
    assert make_effect("thrust_mismatch", rotor_1=-0.1, alpha=0.2,
                       torque_share=0.0).rotor_speed_factor(4) is None
    half = make_effect("thrust_mismatch", rotor_1=-0.1, alpha=0.2, torque_share=0.5)
    assert half.rotor_speed_factor(4)[0] == pytest.approx(0.95 ** -0.2, rel=1e-15)


def test_thrust_alone_acts_alike_in_both_engines_and_not_as_the_plain_change():
    """Open loop from hover with a small differential, 0.5 s: MuJoCo and the analytic engine
    agree to 1e-4 m and 1e-4 rad (tests/test_effects_engines.py's bound), and the yaw differs
    from the same change with its torque (the share acts)."""
    hover = hover_speed(PARAMS)
    t = np.arange(50) * 0.01
    series = hover * (1 + 0.01 * np.sin(2 * np.pi * t))[:, None] * np.array([1, 1.002, 1, 1])
    sets = [effect_set_from_specs(["thrust_mismatch:rotor_2=-0.05,torque_share=0"]),
            effect_set_from_specs(["thrust_mismatch:rotor_2=-0.05"])]
    start = engines.initial_state(position=np.tile([0.0, 0.0, 1.0], (2, 1)),
                                  velocity=np.zeros((2, 3)), euler=np.zeros((2, 3)))
    runs = [engines.simulate(PARAMS, engine=e, initial=start, rotor_speed_series=series,
                             duration=0.5, control_period=0.01, effects=sets)
            for e in ("mujoco", "analytic")]
    assert np.abs(runs[0].position - runs[1].position).max() <= 1e-4
    assert np.abs(runs[0].quat - runs[1].quat).max() <= 1e-4
    yaw_rate = runs[1].body_rate[:, -1, 2]
    assert abs(yaw_rate[0] - yaw_rate[1]) > 1e-2, yaw_rate


def test_the_reading_holds_the_share_at_zero_through_the_registry():
    """The facts declare a per-rotor reading with the share fixed at 0; the explanation built
    from it carries that value (and the rotor's deviation alone as its free parameter)."""
    facts = EFFECTS["thrust_mismatch"].facts
    alone = [r for r in facts.readings if dict(r.fixed).get("torque_share") == 0.0]
    assert len(alone) == 1 and alone[0].per_rotor and alone[0].fitted == ("rotor_{}",)
    expl = _reading(EFFECTS["thrust_mismatch"], alone[0], prior_spreads(PARAMS), (0.2, 0.1),
                    rotor=3, log_prior=0.0)
    assert expl.fixed_values == {"thrust_mismatch.torque_share": 0.0}
    assert expl.parameter_names == ["thrust_mismatch.rotor_3"]
    assert expl.mean == (0.0,) and expl.sd == (pytest.approx(0.1),)


def _row(name, variant, fixed, params, log_z):
    expl = types.SimpleNamespace(variant=variant, fixed_values=fixed, parameter_names=params)
    return types.SimpleNamespace(name=name, explanation=expl, log_z=log_z)


def test_form_words_state_the_pair_shares_below_95_percent():
    """Two forms of one rotor's reading (same parameter, another fixed share): at 1.5 log
    units apart the lead form holds 1 / (1 + e^-1.5) = 81.8 %, stated; at 3.0 (95.3 %, above
    FORM_TOLD) nothing is said; another rotor's reading (other parameters) and another
    effect are never a form of it; a canted rotor's other rotor (its one_per_rotor index)
    neither."""
    alone = _row("thrust_mismatch", "rotor 3, alone", {"thrust_mismatch.torque_share": 0.0},
                 ["thrust_mismatch.rotor_3"], -10.0)
    plain = _row("thrust_mismatch", "rotor 3", {}, ["thrust_mismatch.rotor_3"], -11.5)
    other = _row("thrust_mismatch", "rotor 2", {}, ["thrust_mismatch.rotor_2"], -10.0)
    mass = _row("mass_offset", "", {}, ["thrust_mismatch.rotor_3"], -10.0)
    text = form_words(alone, [alone, plain, other, mass])
    assert text == " (its form not told apart: this form 82 % against 18 % for 'rotor 3')"
    assert 1 / (1 + np.exp(-1.5)) == pytest.approx(0.818, abs=5e-4)
    far = _row("thrust_mismatch", "rotor 3", {}, ["thrust_mismatch.rotor_3"], -13.0)
    assert form_words(alone, [alone, far]) == "" and FORM_TOLD == 0.95
    cant = [_row("canted_rotor", f"rotor {k}", {"canted_rotor.rotor": float(k)},
                 ["canted_rotor.angle", "canted_rotor.azimuth"], -10.0) for k in (1, 2)]
    assert form_words(cant[0], cant) == ""


def _weighed_form(variant, fixed, log_z):
    """A held-out Weighed of rotor 3's thrust change -10 +- 0.5 % in one form (its total
    evidence ``log_z``: training plus held-out log-likelihood)."""
    from quadsim.gap.diagnose import Weighed

    names = ["thrust_mismatch.rotor_3"]
    expl = types.SimpleNamespace(parts=(("thrust_mismatch", dict(fixed), ("rotor_3",)),),
                                 parameter_names=names, mean=(0.0,), sd=(0.1,),
                                 variant=variant, fixed_values=dict(fixed), replaces=())
    ev = types.SimpleNamespace(name="thrust_mismatch", explanation=expl, air_force=None,
                               values={names[0]: -0.1}, post_sd={names[0]: 0.005},
                               determined={names[0]: True}, log_z=log_z)
    return Weighed(ev, ev, [], [], 0.0)


def test_heldout_readings_say_the_forms_not_told_apart_by_the_same_rule():
    """Held out (quadsim.gap.diagnose.readings_of, what decide states): the thrust-alone form
    ranked at total log evidence -10.0 beside the plain form at -11.5 (weighed, not ranked:
    the posterior groups a reading's forms) ends its words with form_words' own sentence,
    82 % against 18 % (1 / (1 + e^-1.5)), the per-flight rule on the posterior's evidence; the
    plain form 3.5 log units behind (96.7 %, above FORM_TOLD) adds nothing."""
    from quadsim.gap.diagnose import readings_of

    reference = types.SimpleNamespace(params=load_params("crazyflie21"), values=dict,
                                      rotor=True)
    alone = _weighed_form("rotor 3, its thrust alone (drag torque unchanged)",
                          {"thrust_mismatch.torque_share": 0.0}, -10.0)
    plain = _weighed_form("rotor 3", {}, -11.5)
    said = " (its form not told apart: this form 82 % against 18 % for 'rotor 3')"
    assert form_words(alone.total, [alone.total, plain.total]) == said
    rows = readings_of([("thrust_mismatch", 0.9, alone)], reference, pool=(alone, plain))
    assert rows[0].magnitude.endswith(said), rows[0].magnitude
    assert rows[0].magnitude.count("form not told apart") == 1
    far = _weighed_form("rotor 3", {}, -13.5)
    rows = readings_of([("thrust_mismatch", 0.9, alone)], reference, pool=(alone, far))
    assert "form not told apart" not in rows[0].magnitude, rows[0].magnitude
