"""The low-band mechanism regressors of benchmarks/rotation_analysis.py (issue 45): closed forms
of each mechanism's moment on the nano-drone's X frame, and the balance recovers a mechanism
planted in synthetic signals (per log and held out) and leaves an absent one at factor 1."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from benchmarks import rotation_analysis as ra
from quadsim.vehicle.params import load_params

ROOT = Path(__file__).resolve().parent.parent
PARAMS = load_params(ROOT / "models/nanodrone_cf21bl.toml", check=False)
L = 0.0353
B = PARAMS.thrust_factor
R = PARAMS.rotor_radius


def _columns(omega, v, rate=(0.0, 0.0, 0.0), sf=(0.0, 0.0, 0.0)) -> dict:
    mechs = ra.mechanism_columns(PARAMS, np.array([omega], float), np.array([v], float),
                                 np.array([rate], float), np.array([sf], float))
    return {m.name: m.columns[0] for m in mechs}


def test_closed_forms_on_the_x_frame():
    w = 1600.0
    c = _columns([w] * 4, (1.0, 2.0, -0.5), sf=(0.3, -0.7, 9.8))
    speed = np.sqrt(1 + 4 + 0.25)
    np.testing.assert_allclose(c["body_drag"][:, 0], [speed * 2.0, -speed * 1.0])
    np.testing.assert_allclose(c["body_drag"][:, 1], [-0.25, -0.25])
    np.testing.assert_allclose(c["force_lever"][:, 0], [0.7 * PARAMS.mass, 0.3 * PARAMS.mass])
    # equal speeds: the spins cancel, and a vertical velocity gives no differential thrust
    np.testing.assert_allclose(c["hub_roll"][:, 0], [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(c["inflow_split"][:, 0], 0.0, atol=1e-15)
    # per-rotor thrust factors: rotor i's torque less the mean torque per rotor
    omega = np.array([1500.0, 1600.0, 1700.0, 1650.0])
    c = _columns(omega, (0.0, 0.0, 0.0))
    arms = np.cross(PARAMS.rotor_positions, PARAMS.rotor_axes)[:, :2]
    per_rotor = arms * (B * omega ** 2)[:, None]
    np.testing.assert_allclose(c["rotor_scale"], (per_rotor - per_rotor.mean(axis=0)).T)
    # flying +x: rotors 2 and 3 (x < 0) are behind, each weighted 1/sqrt(2); roll cancels,
    # pitch (r x z)_y = -x = +L for both
    c = _columns([w] * 4, (2.0, 0.0, 0.0))
    mu = 2.0 / (w * R)
    expected = 2 * L * B * w ** 2 / np.sqrt(2)
    np.testing.assert_allclose(c["wake_mu"][:, 0], [0.0, expected * mu], atol=1e-15)
    np.testing.assert_allclose(c["wake_mu2"][:, 0], [0.0, expected * mu ** 2], atol=1e-15)
    # a roll rate: each hub's axial velocity omega_x y_i; moment -b Omega omega_x 4 L^2 / R
    c = _columns([w] * 4, (0.0, 0.0, 0.0), rate=(0.5, 0.0, 0.0))
    np.testing.assert_allclose(c["inflow"][:, 0], [-B * w * 0.5 * 4 * L ** 2 / R, 0.0],
                               rtol=1e-12, atol=1e-15)


def _low(seed: int, n: int, scale: float, hi: float = 1.5) -> np.ndarray:
    sos = signal.butter(2, hi, fs=ra.RATE_HZ, output="sos")
    x = signal.sosfiltfilt(sos, np.random.default_rng(seed).standard_normal(n))
    return scale * x / x.std()


def _signals(seed: int, c_flap: float, beta: float, n: int = 4000) -> ra.RotationSignals:
    """Roll/pitch torques that the body shows only in part: ``M - tau = c f + beta X`` with X
    the first ``body_drag`` column, plus a small moment of its own."""
    flap = np.column_stack([_low(seed + k, n, 1e3) for k in range(2)])
    x = np.column_stack([_low(seed + 3 + k, n, 0.5) for k in range(2)])
    other = np.column_stack([_low(seed + 6 + k, n, 3.0) for k in range(2)])
    moment = np.column_stack([_low(seed + 9 + k, n, 2e-6) for k in range(2)])
    torque = moment - c_flap * flap - beta * x
    mech = ra.Mechanism("body_drag", ("a", "b"), np.stack([x, other], axis=-1))
    return ra.RotationSignals(name=f"s{seed}", torque=torque, moment=moment, flapping=flap,
                              rate=np.zeros((n, 2)), instrument=None, thrust=np.ones(n),
                              force_z=None, mechanisms=(mech,))


@pytest.mark.parametrize("axis", [0, 1])
def test_balance_recovers_a_planted_mechanism(axis):
    c_flap, beta = 1e-7, -1e-4
    train = [_signals(10 * k, c_flap, beta) for k in range(3)]
    held = [_signals(100, c_flap, beta)]
    out = ra.mechanism_balance(train, held, axis, ("body_drag",))
    coef = out["pooled"]["coef"]
    np.testing.assert_allclose(coef[:2], [c_flap, beta], rtol=0.05)
    assert abs(coef[2]) < 0.05 * abs(beta)                 # the absent second column
    for entry in out["per_log"].values():
        np.testing.assert_allclose(entry["coef"][1], beta, rtol=0.05)
        assert entry["factor"] > 5
    assert out["pooled"]["heldout"]["s100"]["factor"] > 5


def test_absent_mechanism_leaves_factor_one():
    train = [_signals(10 * k, 1e-7, 0.0) for k in range(3)]
    held = [_signals(100, 1e-7, 0.0)]
    out = ra.mechanism_balance(train, held, 0, ("body_drag",))
    np.testing.assert_allclose(out["pooled"]["heldout"]["s100"]["factor"], 1.0, atol=0.05)


def test_air_field_columns_level_vehicle():
    """Level attitude: world x wind shows as -sum Omega on pitch, world y as +sum Omega on
    roll; the position columns are those times the position less its mean."""
    omega = np.full((3, 4), 1000.0)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    pos = np.array([[0.0, 0.0, 1.0], [1.0, 2.0, 1.0], [2.0, 4.0, 1.0]])
    m = ra.air_field_columns(omega, quat, pos)
    np.testing.assert_allclose(m.columns[:, :, 0], [[0.0, -4000.0]] * 3)
    np.testing.assert_allclose(m.columns[:, :, 4], [[4000.0, 0.0]] * 3)
    np.testing.assert_allclose(m.columns[:, 1, 1], [4000.0, 0.0, -4000.0])
    np.testing.assert_allclose(m.columns[:, :, 3], 0.0)
