"""Every effect acts identically in the MuJoCo and the analytic engine.

One batch per engine carries every effect at a realistic magnitude for the 0.84 kg testbed
(wind together with the drag effects it feeds), flying open loop from a moving, slightly
tilted start 0.3 m above the ground with a thrust wobble. The tests run briefly to stay fast
(0.3 s for the batch, 0.5 s for motor lag); ``scripts/effects_agreement.py`` runs the check
over 5 s open loop and 20 s closed loop (results in docs/effects.md).
Tolerance: 1e-4 m in position and 1e-4 rad in attitude (the agreement issue's open-loop bound).
"""

from __future__ import annotations

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.core.frames import quat_conjugate, quat_multiply
from quadsim.effects import TESTBED_EXAMPLES, effect_set_from_specs
from quadsim.sim import engines
from quadsim.vehicle.params import hover_speed, load_params

PARAMS = load_params("physical")
HOVER = hover_speed(PARAMS)
PERIOD = 0.01
DURATION = 0.5
SHORT = 0.3  # the all-effects batch (11 flights) runs shorter to keep the suite fast
TOLERANCE_M = 1e-4
TOLERANCE_RAD = 1e-4

# Every effect but those tested on their own below (gyroscopic in test_agreement.py;
# battery_sag adds rotor-speed states, which a batch has in every simulation or none).
REALISTIC = {name: specs for name, specs in TESTBED_EXAMPLES.items()
             if name not in ("motor_lag", "gyroscopic", "battery_sag")}


def _start(batch: int) -> dict:
    def tile(v):
        return np.tile(v, (batch, 1))
    return engines.initial_state(position=tile([0.0, 0.0, 0.3]), velocity=tile([3.0, -2.0, 0.5]),
                                 euler=tile([0.02, -0.01, 0.2]))


def _both(sets: list, series: np.ndarray, duration: float):
    start = _start(len(sets))
    def run(engine):
        return engines.simulate(
            PARAMS, engine=engine, initial=start, rotor_speed_series=series, duration=duration,
            control_period=PERIOD, effects=sets)
    return run("mujoco"), run("analytic")


def _errors(m, a) -> tuple[np.ndarray, np.ndarray]:
    position = np.abs(m.position - a.position).max(axis=(1, 2))
    relative = quat_multiply(quat_conjugate(m.quat), a.quat)
    angle = 2 * np.arcsin(np.clip(np.linalg.norm(relative[..., 1:], axis=-1), 0, 1)).max(1)
    return position, angle


def test_each_effect_agrees_between_engines():
    sets = [effect_set_from_specs(s) for s in REALISTIC.values()]
    t = np.arange(round(SHORT / PERIOD)) * PERIOD
    # collective wobble plus a small roll/pitch differential, so inertia errors show
    series = HOVER * (1 + 0.01 * np.sin(2 * np.pi * 0.7 * t))[:, None] \
        * np.array([1.0, 1.002, 1.0, 0.999])
    m, a = _both(sets, series, SHORT)
    position, angle = _errors(m, a)
    for name, dp, da in zip(REALISTIC, position, angle):
        assert dp <= TOLERANCE_M and da <= TOLERANCE_RAD, f"{name}: {dp:.3g} m, {da:.3g} rad"
    # each effect really acted: the runs differ from the effect-free flight by more than
    # twice the agreement tolerance
    plain = engines.simulate(PARAMS, engine="analytic", initial=_start(1), duration=SHORT,
                             rotor_speed_series=series, control_period=PERIOD)
    moved = np.abs(a.position - plain.position[0]).max(axis=(1, 2)) + \
        np.abs(a.quat - plain.quat[0]).max(axis=(1, 2))
    for name, change in zip(REALISTIC, moved):
        assert change > 2 * TOLERANCE_M, f"{name} changed the flight by only {change:.3g}"


def test_motor_lag_agrees_between_engines():
    sets = [effect_set_from_specs(["motor_lag:time_constant=0.03,time_constant_down=0.05"])]
    t = np.arange(int(round(DURATION / PERIOD))) * PERIOD
    steps = np.where((t // 0.25) % 2 == 0, 1.03, 0.97)  # up 0.25 s, down 0.25 s
    series = HOVER * steps[:, None] * np.array([1.0, 1.01, 1.0, 0.99])
    m, a = _both(sets, series, DURATION)
    position, angle = _errors(m, a)
    assert position[0] <= TOLERANCE_M and angle[0] <= TOLERANCE_RAD
    # closed form of the first-order lag, rotor 1: up from hover for 0.25 s (tau 0.03 s),
    # then down for 0.25 s (tau 0.05 s)
    k = int(round(0.25 / PERIOD))
    up, down = series[0, 0], series[k, 0]
    after_up = up + (HOVER - up) * np.exp(-0.25 / 0.03)
    after_down = down + (after_up - down) * np.exp(-0.25 / 0.05)
    np.testing.assert_allclose(a.rotor_speed[0, [k, 2 * k], 0], [after_up, after_down],
                               rtol=1e-9)
    np.testing.assert_allclose(m.rotor_speed, a.rotor_speed, rtol=1e-9)


def test_battery_sag_acts_on_the_speed_a_command_gives():
    """Battery sag lowers the rotor speed of a command (not the thrust of a speed): both
    engines agree, and the speed settles at sqrt(1 - rate t) times the command."""
    sets = [effect_set_from_specs(list(TESTBED_EXAMPLES["battery_sag"]))]
    t = np.arange(int(round(DURATION / PERIOD))) * PERIOD
    series = HOVER * np.ones((len(t), 1)) * np.array([1.0, 1.01, 1.0, 0.99])
    m, a = _both(sets, series, DURATION)
    position, angle = _errors(m, a)
    assert position[0] <= TOLERANCE_M and angle[0] <= TOLERANCE_RAD
    end = a.t[0, -1] if a.t.ndim > 1 else a.t[-1]
    expected = series[0] * np.sqrt(1 - 0.01 * end)  # settled (5 ms response << 0.5 s)
    np.testing.assert_allclose(a.rotor_speed[0, -1], expected, rtol=1e-4)
    np.testing.assert_allclose(m.rotor_speed, a.rotor_speed, rtol=1e-6)


def test_a_propeller_change_acts_on_the_speed_a_command_gives():
    """thrust_factor with alpha: a command gives (1 + change)^-alpha of its speed (the
    motor's load changed); both engines (MuJoCo on the compiled path, analytic) agree, and the
    speed settles there (5 ms response << 0.5 s)."""
    sets = [effect_set_from_specs(["thrust_factor:change=-0.1,alpha=0.2"])]
    t = np.arange(int(round(DURATION / PERIOD))) * PERIOD
    series = HOVER * np.ones((len(t), 1)) * np.array([1.0, 1.01, 1.0, 0.99])
    m, a = _both(sets, series, DURATION)
    position, angle = _errors(m, a)
    assert position[0] <= TOLERANCE_M and angle[0] <= TOLERANCE_RAD
    np.testing.assert_allclose(a.rotor_speed[0, -1], series[0] * 0.9 ** -0.2, rtol=1e-4)
    np.testing.assert_allclose(m.rotor_speed, a.rotor_speed, rtol=1e-6)


def test_one_propellers_change_acts_on_its_own_rotors_speed():
    """thrust_mismatch with alpha: rotor 2's command gives (1 - 0.12)^-0.2 of its speed, the
    others are untouched; both engines (MuJoCo on the compiled path, analytic) agree, and the
    speeds settle there (5 ms response << 0.5 s)."""
    sets = [effect_set_from_specs(["thrust_mismatch:rotor_2=-0.12,alpha=0.2"])]
    t = np.arange(int(round(DURATION / PERIOD))) * PERIOD
    series = HOVER * np.ones((len(t), 1)) * np.array([1.0, 1.01, 1.0, 0.99])
    m, a = _both(sets, series, DURATION)
    position, angle = _errors(m, a)
    assert position[0] <= TOLERANCE_M and angle[0] <= TOLERANCE_RAD
    np.testing.assert_allclose(a.rotor_speed[0, -1],
                               series[0] * np.array([1.0, 0.88 ** -0.2, 1.0, 1.0]), rtol=1e-4)
    np.testing.assert_allclose(m.rotor_speed, a.rotor_speed, rtol=1e-6)
    with pytest.raises(InputError, match=r"thrust_mismatch: alpha = 0.9 .* \[0, 0.5\]"):
        effect_set_from_specs(["thrust_mismatch:rotor_2=-0.1,alpha=0.9"])


def test_a_propeller_change_scales_the_thrust_curve_in_both_engines():
    """thrust_factor scales a thrust curve's terms with b Omega^2 (EffectLoads.curve_offset)
    in both engines alike: a curve with a 10 % weaker propeller flies as the vehicle whose b,
    d and curve terms are all 10 % lower, not as the one whose curve kept its terms."""
    import dataclasses

    sets = [effect_set_from_specs(["thrust_curve:linear=-2e-4,offset=0.05",
                                   "thrust_factor:change=-0.1"])]
    t = np.arange(round(SHORT / PERIOD)) * PERIOD
    series = HOVER * (1 + 0.01 * np.sin(2 * np.pi * 0.7 * t))[:, None] \
        * np.array([1.0, 1.002, 1.0, 0.999])
    m, a = _both(sets, series, SHORT)
    position, angle = _errors(m, a)
    assert position[0] <= TOLERANCE_M and angle[0] <= TOLERANCE_RAD
    weaker = dataclasses.replace(PARAMS, thrust_factor=0.9 * PARAMS.thrust_factor,
                                 drag_factor=0.9 * PARAMS.drag_factor)
    def run(curve):
        return engines.simulate(
            weaker, engine="analytic", initial=_start(1), duration=SHORT, control_period=PERIOD,
            rotor_speed_series=series, effects=[effect_set_from_specs([curve])])
    scaled, kept = run("thrust_curve:linear=-1.8e-4,offset=0.045"), \
        run("thrust_curve:linear=-2e-4,offset=0.05")
    np.testing.assert_allclose(a.position, scaled.position, atol=1e-9)
    assert np.abs(a.position - kept.position).max() > 2 * TOLERANCE_M
