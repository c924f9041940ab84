"""Each effect's sign and magnitude against a hand calculation, batching, and the registry."""

from __future__ import annotations

import re

import numpy as np
import pytest

from quadsim.core.errors import InputError, ModelError
from quadsim.core.frames import euler_to_quat
from quadsim.effects import (
    EFFECTS,
    EffectContext,
    EffectSet,
    describe_effects,
    effect_set_from_specs,
    make_effect,
    parse_effect_spec,
)
from quadsim.vehicle.params import hover_speed, load_params
from quadsim.vehicle.rotors import rotor_wrench

PARAMS = load_params("physical")
HOVER = hover_speed(PARAMS)


def context(*, position=(0.0, 0.0, 1.0), velocity=(0.0, 0.0, 0.0), euler=(0.0, 0.0, 0.0),
            wind=(0.0, 0.0, 0.0), speed=None, t=0.0, vbat=None, params=PARAMS,
            body_rate=(0.0, 0.0, 0.0)):
    """A one-simulation EffectContext (B = 1)."""
    speed = np.full(params.rotor_count, HOVER) if speed is None else np.asarray(speed, float)
    def row(v):
        return np.asarray(v, dtype=float)[None]
    return EffectContext(t=np.array([t]), position=row(position), velocity=row(velocity),
                         quat=row(euler_to_quat(np.asarray(euler, float))),
                         body_rate=row(body_rate),
                         air_velocity=row(velocity) - row(wind), rotor_speed=row(speed),
                         rotor_accel=np.zeros((1, params.rotor_count)), params=params,
                         vbat=None if vbat is None else np.array([vbat]))


def test_every_effect_is_off_by_default():
    ctx = context(velocity=(5.0, 0.0, 0.0), position=(0.0, 0.0, 0.1))
    for name, cls in EFFECTS.items():
        effect = cls()
        assert effect.is_off(), name
        assert effect.apply_to_params(PARAMS) is PARAMS, name
        assert effect.rotor_speed_rate(np.zeros(1), np.ones((1, 4)), np.zeros((1, 4))) is None
        loads = effect.loads(ctx)
        if loads is not None:
            np.testing.assert_array_equal(loads.thrust_scale, 1.0, err_msg=name)
            np.testing.assert_array_equal(loads.thrust_offset, 0.0, err_msg=name)
            np.testing.assert_array_equal(loads.curve_offset, 0.0, err_msg=name)
            np.testing.assert_array_equal(loads.force_world, 0.0, err_msg=name)
            np.testing.assert_array_equal(loads.torque_body, 0.0, err_msg=name)
        wind = effect.air_velocity(np.zeros(1), np.zeros((1, 3)))
        assert wind is None or not np.any(wind), name


def test_every_effect_documents_formula_source_and_units():
    for name, cls in EFFECTS.items():
        doc = __import__(cls.__module__, fromlist=["_"]).__doc__
        # the effect's name, a formula, and a dated published source
        assert doc and name in doc and " = " in doc and re.search(r"\b(19|20)\d\d\b", doc), name
        assert all(p.unit and p.doc and p.lower <= p.off <= p.upper for p in cls.parameters)


def test_motor_lag_rate_up_and_down():
    lag = make_effect("motor_lag", time_constant=0.02, time_constant_down=0.05)
    command = np.array([[500.0, 300.0, 400.0, 400.0]])
    actual = np.array([[400.0, 400.0, 400.0, 300.0]])
    rate = lag.rotor_speed_rate(np.zeros(1), command, actual)
    np.testing.assert_allclose(rate, [[100 / 0.02, -100 / 0.05, 0.0, 100 / 0.02]])
    same = make_effect("motor_lag", time_constant=0.04)
    np.testing.assert_allclose(same.rotor_speed_rate(np.zeros(1), command, actual)[0, 1],
                               -100 / 0.04)


def test_thrust_curve_adds_linear_and_constant_thrust():
    curve = make_effect("thrust_curve", linear=-2e-4, offset=0.01)
    loads = curve.loads(context(speed=[400.0, 450.0, 500.0, 550.0]))
    np.testing.assert_allclose(loads.curve_offset, [[-0.07, -0.08, -0.09, -0.1]], atol=1e-15)


def test_thrust_curve_curvature_acts_about_its_centre():
    """``quadratic (W - c)^2 + linear (W - c) + offset`` (module doc): zero curvature
    term at the centre, symmetric about it."""
    curve = make_effect("thrust_curve", linear=1e-4, quadratic=-2e-6, centre=450.0,
                        offset=0.01)
    loads = curve.loads(context(speed=[400.0, 450.0, 500.0, 550.0]))
    expected = [1e-4 * d - 2e-6 * d * d + 0.01 for d in (-50.0, 0.0, 50.0, 100.0)]
    np.testing.assert_allclose(loads.curve_offset, [expected], atol=1e-15)
    assert expected == pytest.approx([0.0, 0.01, 0.01, 0.0], abs=1e-12)


def test_a_propeller_change_scales_its_whole_thrust_curve():
    """thrust_factor scales b Omega^2 and the curve's linear and constant terms alike (a
    stand fit c0 + c1 a + c2 a^2 of a propeller giving 10 % less thrust has every coefficient
    10 % lower); a translational lift, not part of the curve, is not scaled."""
    from quadsim.effects.base import EffectSet
    from quadsim.gap.residual import rotor_wrench

    speed = np.array([[400.0, 450.0, 500.0, 550.0]])
    curve = make_effect("thrust_curve", linear=-2e-4, offset=0.01)
    both = EffectSet((curve, make_effect("thrust_factor", change=-0.1))).loads(
        context(speed=speed[0]))
    np.testing.assert_allclose(both.rotor_offset, 0.9 * (-2e-4 * speed + 0.01), rtol=1e-12)
    force = rotor_wrench(PARAMS, both, speed)[0, 2]
    expected = 0.9 * np.sum(PARAMS.thrust_factor * speed ** 2 - 2e-4 * speed + 0.01)
    assert force == pytest.approx(expected, rel=1e-12)


def test_thrust_mismatch_scales_named_rotor():
    loads = make_effect("thrust_mismatch", rotor_2=-0.05, rotor_4=0.02).loads(context())
    np.testing.assert_allclose(loads.thrust_scale, [[1.0, 0.95, 1.0, 1.02]])
    with pytest.raises(ModelError, match="beyond the vehicle's 4 rotors"):
        make_effect("thrust_mismatch", rotor_6=0.1).loads(context())


def test_rotor_drag_at_5_m_s():
    drag = make_effect("rotor_drag", coefficient=1e-5, axial_coefficient=4e-6)
    # level, 5 m/s forward: F = -k * 4 * Omega * 5 along -x, no net torque (symmetric)
    loads = drag.loads(context(velocity=(5.0, 0.0, 0.0)))
    np.testing.assert_allclose(loads.force_world, [[-1e-5 * 4 * HOVER * 5.0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(loads.torque_body, 0.0, atol=1e-12)
    # climbing at 5 m/s: only the axial coefficient acts
    loads = drag.loads(context(velocity=(0.0, 0.0, 5.0)))
    np.testing.assert_allclose(loads.force_world, [[0, 0, -4e-6 * 4 * HOVER * 5.0]], atol=1e-12)
    # yawed 90 deg, flying in wind of 5 m/s along y (vehicle still): force along +y (downwind)
    loads = drag.loads(context(euler=(0, 0, np.pi / 2), wind=(0, 5.0, 0)))
    np.testing.assert_allclose(loads.force_world, [[0, 1e-5 * 4 * HOVER * 5.0, 0]], atol=1e-12)
    # one rotor faster: the force at its hub (+x arm) gives a yaw torque r x F
    speed = np.array([HOVER + 100, HOVER, HOVER, HOVER])
    loads = drag.loads(context(velocity=(0.0, 5.0, 0.0), speed=speed))
    arm = PARAMS.rotor_positions[0, 0]
    np.testing.assert_allclose(loads.torque_body[0, 2], arm * (-1e-5 * 100 * 5.0), rtol=1e-12)


def test_rotor_drag_damps_a_yaw_at_hover():
    """Hovering, yawing at 2 rad/s: each hub moves at w x (r_i - c) in the rotor plane, so the
    in-plane drag damps the yaw, tau_z = -k sum_i Omega_i |r_i - c|^2 w_z (module doc), with
    no net force (the hub velocities cancel in pairs)."""
    drag = make_effect("rotor_drag", coefficient=1e-5, axial_coefficient=4e-6)
    loads = drag.loads(context(body_rate=(0.0, 0.0, 2.0)))
    arms = PARAMS.rotor_positions - PARAMS.com
    planar = np.sum(arms[:, :2] ** 2, axis=1)
    np.testing.assert_allclose(loads.torque_body[0, 2], -1e-5 * HOVER * planar.sum() * 2.0,
                               rtol=1e-9)
    np.testing.assert_allclose(loads.force_world, 0.0, atol=1e-12)


def test_body_drag_at_5_m_s():
    drag = make_effect("body_drag", cd_area=0.01, cd_area_vertical=0.03)
    loads = drag.loads(context(velocity=(5.0, 0.0, 0.0)))
    np.testing.assert_allclose(loads.force_world, [[-0.5 * 1.225 * 0.01 * 25.0, 0, 0]])
    loads = drag.loads(context(velocity=(0.0, 0.0, -5.0)))
    np.testing.assert_allclose(loads.force_world, [[0, 0, 0.5 * 1.225 * 0.03 * 25.0]])
    # pitched 90 deg: the body z axis faces the flow, so the vertical area acts along x
    loads = drag.loads(context(velocity=(5.0, 0.0, 0.0), euler=(0.0, np.pi / 2, 0.0)))
    np.testing.assert_allclose(loads.force_world, [[-0.5 * 1.225 * 0.03 * 25.0, 0, 0]],
                               atol=1e-12)


def test_body_drag_per_axis_on_a_diagonal():
    """Air at 5 m/s along the body's xy diagonal (3.536 m/s on x and on y): the law on the
    air speed gives each axis -1/2 rho C_dA |v| v_i, the per-axis law -1/2 rho C_dA |v_i|
    v_i, 1/sqrt(2) of it; along one axis the two agree."""
    v = 5.0 / np.sqrt(2.0)
    norm = make_effect("body_drag", cd_area=0.01).loads(context(velocity=(v, v, 0.0)))
    axes = make_effect("body_drag", cd_area=0.01, per_axis=1.0).loads(
        context(velocity=(v, v, 0.0)))
    np.testing.assert_allclose(norm.force_world, [[-0.5 * 1.225 * 0.01 * 5.0 * v] * 2 + [0]],
                               rtol=1e-12)
    np.testing.assert_allclose(axes.force_world, [[-0.5 * 1.225 * 0.01 * v * v] * 2 + [0]],
                               rtol=1e-12)
    one = [make_effect("body_drag", cd_area=0.01, per_axis=k).loads(
        context(velocity=(5.0, 0.0, 0.0))).force_world for k in (0.0, 1.0)]
    np.testing.assert_allclose(one[0], one[1], rtol=1e-12)


def test_ground_effect_at_z_equal_radius():
    radius = PARAMS.rotor_radius
    ground = make_effect("ground_effect", gain=1.5)
    loads = ground.loads(context(position=(0.0, 0.0, radius)))
    np.testing.assert_allclose(loads.thrust_scale, 1.0 / (1.0 - 1.5 / 16.0), rtol=1e-12)
    # raised ground and a tilt: each hub at its own height
    tilted = make_effect("ground_effect", gain=1.0, ground_height=0.5)
    roll = 0.2
    loads = tilted.loads(context(position=(0.0, 0.0, 0.5 + radius), euler=(roll, 0.0, 0.0)))
    arm = PARAMS.rotor_positions[1, 1]  # rotor 2 at -y goes down when rolling right (+)
    heights = radius + np.array([0.0, arm * np.sin(roll), 0.0, -arm * np.sin(roll)])
    np.testing.assert_allclose(loads.thrust_scale[0], 1 / (1 - (radius / (4 * heights)) ** 2))
    far = ground.loads(context(position=(0.0, 0.0, 10.0))).thrust_scale
    assert np.all(far - 1.0 < 1e-3)
    with pytest.raises(ModelError, match="rotor_radius"):
        ground.loads(context(params=PARAMS.replace(rotor_radius=0.0)))


def test_battery_sag_time_and_voltage():
    sag = make_effect("battery_sag", rate=0.01, full_voltage=4.2)
    # the battery acts on the speed a command gives, never on the thrust of a speed
    assert sag.loads(context(t=10.0)) is None
    np.testing.assert_allclose(sag.speed_factor(np.array([10.0])), np.sqrt(0.9))
    np.testing.assert_allclose(sag.voltage(np.array([10.0])), 4.2 * np.sqrt(0.9))
    np.testing.assert_allclose(sag.speed_factor(np.array([3.0]), np.array([3.78])), 0.9)
    assert make_effect("battery_sag").speed_factor(np.array([1.0])) is None


def test_com_offset_hover_torque():
    shifted = make_effect("com_offset", x=0.01, y=-0.004).apply_to_params(PARAMS)
    np.testing.assert_allclose(shifted.com, [0.01, -0.004, 0.0])
    _, torque = rotor_wrench(shifted, np.full(4, HOVER))
    weight = 4 * PARAMS.thrust_factor * HOVER**2
    # equal thrusts act at the geometric centre: torque = (0 - c) x (0, 0, T)
    np.testing.assert_allclose(torque, np.cross(-shifted.com, [0, 0, weight]), atol=1e-12)


def test_mass_offset_against_composite_inertia():
    payload = make_effect("mass_offset", mass=0.1, x=0.02, y=-0.01, z=-0.05)
    new = payload.apply_to_params(PARAMS)
    point = np.array([0.02, -0.01, -0.05])
    assert new.mass == pytest.approx(PARAMS.mass + 0.1)
    np.testing.assert_allclose(new.com, 0.1 * point / new.mass)
    # independent route: both bodies' inertia about the body origin, then shift to the CoM
    about_origin = PARAMS.inertia + 0.1 * (point @ point * np.eye(3) - np.outer(point, point))
    c = new.com
    expected = about_origin - new.mass * (c @ c * np.eye(3) - np.outer(c, c))
    np.testing.assert_allclose(new.inertia, expected, rtol=1e-12, atol=1e-15)


def test_inertia_error_scales_moments_and_checks_triangle():
    new = make_effect("inertia_error", xx=0.2, zz=-0.1).apply_to_params(PARAMS)
    np.testing.assert_allclose(np.diag(new.inertia), np.diag(PARAMS.inertia) * [1.2, 1.0, 0.9])
    with pytest.raises(ModelError):
        make_effect("inertia_error", zz=1.5).apply_to_params(PARAMS)  # Izz > Ixx + Iyy


def test_wind_mean_rms_and_seed():
    wind = make_effect("wind", vx=2.0, vy=-1.0, gust=0.5, bandwidth=2.0, seed=3)
    t = np.arange(0.0, 2000.0, 0.05)
    w = wind.air_velocity(t, np.zeros((len(t), 3)))
    np.testing.assert_allclose(w.mean(axis=0), [2.0, -1.0, 0.0], atol=0.05)
    np.testing.assert_allclose(w.std(axis=0), 0.5, rtol=0.05)
    again = make_effect("wind", vx=2.0, vy=-1.0, gust=0.5, bandwidth=2.0, seed=3)
    np.testing.assert_array_equal(again.air_velocity(t[:100], None), w[:100])
    other = make_effect("wind", vx=2.0, vy=-1.0, gust=0.5, bandwidth=2.0, seed=4)
    assert np.abs(other.air_velocity(t[:100], None) - w[:100]).max() > 0.1


def test_loads_are_vectorised_over_the_batch():
    rng = np.random.default_rng(0)
    batch = 5
    t = rng.uniform(0, 10, batch)
    position = rng.normal(size=(batch, 3)) * 0.2 + [0, 0, 0.4]
    velocity = rng.normal(size=(batch, 3)) * 3
    euler = rng.normal(size=(batch, 3)) * 0.3
    speed = HOVER + rng.normal(size=(batch, 4)) * 30
    big = EffectContext(t=t, position=position, velocity=velocity, quat=euler_to_quat(euler),
                        body_rate=np.zeros((batch, 3)), air_velocity=velocity,
                        rotor_speed=speed, rotor_accel=np.zeros((batch, 4)), params=PARAMS)
    specs = ["thrust_curve:linear=-2e-4", "thrust_mismatch:rotor_1=0.03",
             "rotor_drag:coefficient=1e-5,axial_coefficient=5e-6",
             "body_drag:cd_area=0.02", "ground_effect:gain=1.5", "battery_sag:rate=0.01"]
    effects = effect_set_from_specs(specs)
    whole = effects.loads(big)
    for b in range(batch):
        one = effects.loads(context(position=position[b], velocity=velocity[b], euler=euler[b],
                                    speed=speed[b], t=t[b]))
        for name in ("thrust_scale", "thrust_offset", "force_world", "torque_body", "curve_offset"):
            np.testing.assert_allclose(getattr(whole, name)[b], getattr(one, name)[0],
                                       rtol=1e-12, atol=1e-15)


def test_registry_parsing_and_errors():
    effect = parse_effect_spec("ground_effect:gain=1.2, ground_height=0.1")
    assert effect.values() == {"gain": 1.2, "ground_height": 0.1, "radius": 0.0}
    assert parse_effect_spec("motor_lag").is_off()
    with pytest.raises(InputError, match="unknown effect"):
        parse_effect_spec("ground_efect:gain=1")
    with pytest.raises(InputError, match="unknown parameter 'gian'"):
        parse_effect_spec("ground_effect:gian=1")
    with pytest.raises(InputError, match="'abc' is not a number"):
        parse_effect_spec("ground_effect:gain=abc")
    with pytest.raises(InputError, match=r"time_constant = -1 s outside the plausible range "
                                         r"\[0, [0-9.]+\] s$"):
        parse_effect_spec("motor_lag:time_constant=-1")
    # a dimensionless value ("1") is written bare, not "99 1"
    with pytest.raises(InputError, match=r"gain = 99 outside the plausible range \[0, 5\]$"):
        parse_effect_spec("ground_effect:gain=99")
    with pytest.raises(InputError, match="more than once"):
        effect_set_from_specs(["wind:vx=1", "wind:vy=1"])
    described = describe_effects(EffectSet((effect,)))
    assert described == [{"name": "ground_effect", "values": effect.values(),
                          "units": {"gain": "1", "ground_height": "m", "radius": "m"}}]


def _moved_vehicle_fields(params):
    """(field name, a copy of ``params`` with that dataclass field moved) for every field."""
    import dataclasses

    out = []
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if isinstance(value, bool) or value is None:
            continue
        if isinstance(value, float | int):
            moved = value * 1.1 + 0.01
        elif isinstance(value, np.ndarray):
            moved = value + 0.01
        elif f.name == "rotors":
            moved = tuple(dataclasses.replace(r, position=r.position + 0.01,
                                              axis=(r.axis + 0.1) / np.linalg.norm(r.axis + 0.1),
                                              spin=-r.spin) for r in value)
        elif isinstance(value, str):
            moved = value + "x"
        else:
            continue
        out.append((f.name, dataclasses.replace(params, **{f.name: moved})))
    return out


@pytest.mark.parametrize("name", sorted(n for n, c in EFFECTS.items()
                                        if getattr(c, "loads_reads", None) is not None))
def test_loads_read_only_what_they_declare(name):
    """An effect's ``loads_reads`` (what a caller keeps its loads by) names everything its
    loads read: moving any other context field or vehicle attribute leaves them the same
    to the bit, and moving the declared ones changes them."""
    cls = EFFECTS[name]
    values = {p.name: p.off + 0.3 * ((p.upper if p.upper > p.off else p.lower) - p.off)
              for p in cls.parameters}
    effect = cls(**values)
    rng = np.random.default_rng(1)
    batch = 6

    def ctx(params=PARAMS, **fields):
        base = dict(t=np.linspace(0, 1, batch), position=rng.normal(size=(batch, 3)),
                    velocity=np.ones((batch, 3)), quat=euler_to_quat(np.full((batch, 3), 0.2)),
                    body_rate=np.full((batch, 3), 0.3), air_velocity=np.full((batch, 3), 2.0),
                    rotor_speed=HOVER + np.arange(batch * 4.0).reshape(batch, 4),
                    rotor_accel=np.arange(batch * 4.0).reshape(batch, 4) ** 2,
                    vbat=np.full(batch, 3.9))
        base.update(fields)
        return EffectContext(params=params, **base)

    def same(a, b):
        return all(np.array_equal(getattr(a, f), getattr(b, f))
                   for f in ("thrust_scale", "thrust_offset", "force_world", "torque_body",
                             "curve_offset"))

    fields, attributes = cls.loads_reads
    first = effect.loads(ctx())
    others = {"air_velocity": rng.normal(size=(batch, 3)),
              "rotor_speed": HOVER + rng.normal(size=(batch, 4)) * 100,
              "rotor_accel": rng.normal(size=(batch, 4)) * 100, "vbat": np.full(batch, 3.5)}
    for field, moved in others.items():
        assert same(first, effect.loads(ctx(**{field: moved}))) == (field not in fields), field
    for field, params in _moved_vehicle_fields(PARAMS):
        kept = all(np.array_equal(getattr(params, a), getattr(PARAMS, a)) for a in attributes)
        if kept:
            assert same(first, effect.loads(ctx(params=params))), field
    for attribute in attributes:
        assert any(not np.array_equal(getattr(p, attribute), getattr(PARAMS, attribute))
                   and not same(first, effect.loads(ctx(params=p)))
                   for _, p in _moved_vehicle_fields(PARAMS)), attribute
