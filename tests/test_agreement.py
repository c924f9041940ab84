"""The MuJoCo runner and the analytic Newton–Euler model agree on identical inputs.

Tolerances: <= 1e-4 m and 1e-4 rad over 5 s open loop (hover, a step on each of
collective / roll / pitch / yaw, a seeded random multisine), <= 1e-3 m over 20 s with the LQR
closed loop flying a figure-8, for the ``physical`` and ``computational`` parameter sets. All
cases of one model run as one batch per engine (that is also a test of batching).
"""

import numpy as np

from quadsim.core.frames import quat_conjugate, quat_multiply
from quadsim.effects import EffectSet, make_effect
from quadsim.effects.gyroscopic import Gyroscopic
from quadsim.sim.engines import initial_state, simulate
from quadsim.sim.linear import LQRController, hover_point
from quadsim.vehicle.params import load_params
from quadsim.vehicle.rotors import speeds_for

OPEN_LOOP_S, CLOSED_LOOP_S = 5.0, 20.0
PERIOD = 0.01
CASES = ("hover", "collective", "roll", "pitch", "yaw", "multisine")


def _params(name):
    return load_params(name)


def angle_error(q1, q2):
    """Rotation angle (rad) between two attitude series (..., 4)."""
    rel = quat_multiply(quat_conjugate(q1), q2)
    return 2 * np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))


def open_loop_inputs(params, periods, seed=0):
    """(6, N, R) rotor speed series: hover, then steps of collective thrust (+5 % of weight),
    roll / pitch torque (2e-3 N m) and yaw torque (5e-3 N m) at t = 0.5 s, and a seeded
    multisine on every rotor (5 sines, 0.2-3 Hz, +-3 % of hover speed)."""
    _, hover = hover_point(params)
    t = np.arange(periods) * PERIOD
    on = (t >= 0.5)[:, None]
    weight = params.weight
    steps = {"collective": [0.05 * weight, 0, 0, 0], "roll": [0, 2e-3, 0, 0],
             "pitch": [0, 0, 2e-3, 0], "yaw": [0, 0, 0, 5e-3]}
    series = [np.broadcast_to(hover, (periods, hover.size))]
    for name in CASES[1:5]:
        step = speeds_for(params, np.array([weight, 0, 0, 0]) + steps[name], clip=False)
        series.append(np.where(on, step, hover))
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.2, 3.0, (5, hover.size))
    phase = rng.uniform(0, 2 * np.pi, (5, hover.size))
    wobble = np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None]).sum(1) / 5
    series.append(hover * (1 + 0.03 * wobble))
    return np.stack(series)


def _models():
    """Both parameter sets (computational's mass properties come from the CAD meshes)."""
    return [load_params("physical"), load_params("computational")]


def test_open_loop_agreement():
    """Both models x six input cases, one batch of 12 per engine."""
    models = _models()
    periods = int(OPEN_LOOP_S / PERIOD)
    params = [p for p in models for _ in CASES]
    series = np.concatenate([open_loop_inputs(p, periods) for p in models])
    start = initial_state(position=(0, 0, 1), euler=(0.261, 0.261, 0.261))
    runs = {engine: simulate(params, engine=engine, initial=start, rotor_speed_series=series,
                             duration=OPEN_LOOP_S, control_period=PERIOD)
            for engine in ("mujoco", "analytic")}
    m, a = runs["mujoco"], runs["analytic"]
    assert m.position.shape == (len(params), periods + 1, 3)
    position_error = np.abs(m.position - a.position).max(axis=(1, 2))
    attitude_error = angle_error(m.quat, a.quat).max(axis=1)
    names = [f"{p.name} {case}" for p in models for case in CASES]
    for name, dp, da in zip(names, position_error, attitude_error):
        assert dp <= 1e-4, f"{name}: position differs by {dp:.3g} m"
        assert da <= 1e-4, f"{name}: attitude differs by {da:.3g} rad"
    # every input case takes the vehicle somewhere else than hover commands do (an agreement
    # on nothing would prove nothing)
    for first in (0, len(CASES)):
        others = slice(first + 1, first + len(CASES))
        moved = np.linalg.norm(a.position[others, -1] - a.position[first, -1], axis=1) \
            + angle_error(a.quat[others, -1], a.quat[first, -1])
        assert np.all(moved > 0.01), moved


def figure8(t, amplitude=1.0, period=10.0, height=1.0):
    """(B, 12) reference: a figure-8 in the horizontal plane at ``height``."""
    w = 2 * np.pi / period
    ref = np.zeros((np.size(t), 12))
    ref[:, 0], ref[:, 1] = amplitude * np.sin(w * t), 0.5 * amplitude * np.sin(2 * w * t)
    ref[:, 2] = height
    ref[:, 3], ref[:, 4] = amplitude * w * np.cos(w * t), amplitude * w * np.cos(2 * w * t)
    return ref


def test_closed_loop_figure8_agreement_and_return_to_hover():
    """Per model, two simulations: LQR figure-8 tracking, and LQR return to hover from the
    report's initial state (z = 1 m, roll = pitch = yaw = 0.261 rad). Both models run as one
    batch of four per engine."""
    models = _models()
    controllers = []
    for params in models:
        hover_ref = LQRController(params).hover_state

        def reference(t, hover_ref=hover_ref):
            ref = figure8(t)
            ref[1] = hover_ref
            return ref

        controllers.append(LQRController(params, reference=reference))

    def controller(t, state):
        halves = [{k: v[i:i + 2] for k, v in state.items()} for i in (0, 2)]
        return np.concatenate([c(t[i:i + 2], h) for c, h, i in zip(controllers, halves, (0, 2))])

    figure8_start = tuple(figure8(np.zeros(1))[0, 3:6])
    start = initial_state(position=[(0, 0, 1)] * 4,
                          euler=[(0, 0, 0), (0.261, 0.261, 0.261)] * 2,
                          velocity=[figure8_start, (0, 0, 0)] * 2)
    params = [models[0], models[0], models[1], models[1]]
    runs = {engine: simulate(params, engine=engine, initial=start, controller=controller,
                             duration=CLOSED_LOOP_S, control_period=0.02)
            for engine in ("mujoco", "analytic")}
    m, a = runs["mujoco"], runs["analytic"]
    assert np.abs(m.position - a.position).max() <= 1e-3
    assert angle_error(m.quat, a.quat).max() <= 1e-3
    for i in (0, 2):
        tracking = np.linalg.norm(a.position[i] - figure8(a.t)[:, 0:3], axis=1)[a.t > 5].max()
        assert tracking < 0.3, f"figure-8 tracking error {tracking:.3g} m"
    for run in (m, a):
        for i, c in zip((1, 3), controllers):
            final = run.state12()[i, -1]
            assert np.abs(final - c.hover_state).max() < 1e-3, (run.engine, final)


def test_effects_agree_gyroscopic_with_motor_lag():
    """Generic effect hooks: rotor-speed dynamics and a body torque act the same in both
    engines (gyroscopic torque with Jr = 6e-5 kg m^2, 30 ms motor lag, multisine input)."""
    params = load_params("physical")
    duration = 1.0
    series = open_loop_inputs(params, int(duration / PERIOD))[-1]
    start = initial_state(position=(0, 0, 1), euler=(0.261, 0.261, 0.261), body_rate=(1, -1, 2))
    effects = EffectSet((Gyroscopic(rotor_inertia=6e-5),
                         make_effect("motor_lag", time_constant=0.03)))
    runs = {engine: simulate(params, engine=engine, initial=start, rotor_speed_series=series,
                             duration=duration, effects=effects)
            for engine in ("mujoco", "analytic")}
    plain = simulate(params, engine="analytic", initial=start, rotor_speed_series=series,
                     duration=duration)
    m, a = runs["mujoco"], runs["analytic"]
    assert np.abs(m.position - a.position).max() <= 1e-4
    assert angle_error(m.quat, a.quat).max() <= 1e-4
    assert np.abs(m.rotor_speed - a.rotor_speed).max() <= 1e-6
    assert angle_error(plain.quat, a.quat).max() > 1e-2   # the effects do act
