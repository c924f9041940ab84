"""Where the gap lies: by channel, flight regime, frequency band, and k-step prediction error.

All functions take residuals already divided by the per-channel noise scale (so channels
add), and return plain dicts ready for JSON.

Regimes (a sample may be in several; thresholds scale with the vehicle where that matters):
hover (speed < 0.2 m/s and |omega| < 0.5 rad/s), climb (vz > 0.3 m/s), descent
(vz < -0.3 m/s), fast_forward (horizontal speed > 1 m/s), aggressive_rotation
(|omega| > 2 rad/s), near_ground (hub height below 4 rotor radii, or 0.1 m when the radius is
unknown), low_battery (vbat in the lowest 20 % of the log's range; absent without vbat, and
empty when the battery did not discharge: a range below 2 % of the mean voltage
(:data:`MIN_VBAT_DROP`) is noise on a flat signal, not a low battery).

k-step prediction error: from shooting nodes every 0.1 s of each held-out flight, the analytic
rigid-body model (measured rotor speeds, model wrench incl. effects) is integrated forward by
the analytic engine (quadsim.sim.engines.simulate, solve_ivp) with the measured rotor speeds
held over each (decimated) log step; position and attitude errors at horizons
0.05-1 s. Restarting at every node (multiple shooting) keeps an open-loop-unstable model
scoreable.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import welch

from ..core.errors import QuadsimError
from ..core.frames import quat_conjugate, quat_multiply
from ..effects.base import EffectSet
from ..vehicle.params import VehicleParams
from .fitting import residuals
from .residual import FlightStates
from .rotor_channel import rate_owner

__all__ = ["BANDS_HZ", "HORIZONS_S", "by_band", "by_regime", "kstep_errors", "regime_masks",
           "scaled_residuals", "where"]

BANDS_HZ = ((0.0, 1.0), (1.0, 5.0), (5.0, 20.0), (20.0, np.inf))
HORIZONS_S = (0.05, 0.1, 0.2, 0.5, 1.0)


#: the low_battery regime needs the battery to fall by this fraction of its mean voltage
#: over the log (a 1S LiPo falls 4.2 -> 3.7 V, 12 %, over a full flight; 2 % = 80 mV is far
#: above the mV noise of a voltage log).
MIN_VBAT_DROP = 0.02


def scaled_residuals(states: list[FlightStates], params: VehicleParams, effects: list,
                     sigma: np.ndarray, *, rotor: bool) -> list[np.ndarray]:
    """Each flight's residual (N_j, C) under ``params`` plus ``effects``
    (:func:`quadsim.gap.fitting.residuals`) divided by the noise scale ``sigma`` (C,)."""
    return [residuals(s, params, effects, rotor_channel=rotor) / sigma for s in states]


def where(held: list[FlightStates], params: VehicleParams, *, names: list[str],
          sigma: np.ndarray, before: list[np.ndarray], after: list[np.ndarray],
          effects_after: list, base: list, kstep: bool) -> dict:
    """The ``where`` block of a held-out result: per channel (``names``) the noise scale, the
    held-out RMS before and after (channel units) and the share of the squared gap; by
    regime (before and after), by band, and the k-step errors under ``base`` and
    ``effects_after`` (``kstep`` False: empty). ``before``/``after``: the held-out flights'
    residuals over ``sigma`` under the nominal model and with the verdict."""
    masks = [regime_masks(s, params) for s in held]
    dt = float(held[0].t[1] - held[0].t[0])
    energy = np.sum(np.concatenate(before) ** 2, axis=0)

    def rms(scaled):
        return np.sqrt(np.mean(np.concatenate(scaled) ** 2, axis=0)) * sigma

    return {
        "channels": list(names),
        "noise_scale": dict(zip(names, map(float, sigma))),
        "heldout_rms_before": dict(zip(names, map(float, rms(before)))),
        "heldout_rms_after": dict(zip(names, map(float, rms(after)))),
        "channel_share": dict(zip(names, map(float, energy / max(energy.sum(), 1e-300)))),
        "regime": by_regime(before, masks),
        "regime_after": by_regime(after, masks),
        "band": by_band(before, dt),
        "kstep_before": kstep_errors(held, params, list(base)) if kstep else {},
        "kstep_after": kstep_errors(held, params, effects_after) if kstep else {},
    }


def regime_masks(states: FlightStates, params: VehicleParams) -> dict[str, np.ndarray]:
    """Boolean masks (N,) per flight regime (see module docstring)."""
    speed = np.linalg.norm(states.velocity, axis=1)
    rate = np.linalg.norm(states.body_rate, axis=1)
    vz = states.velocity[:, 2]
    ground = 4 * params.rotor_radius if params.rotor_radius > 0 else 0.1
    masks = {
        "hover": (speed < 0.2) & (rate < 0.5),
        "climb": vz > 0.3,
        "descent": vz < -0.3,
        "fast_forward": np.linalg.norm(states.velocity[:, :2], axis=1) > 1.0,
        "aggressive_rotation": rate > 2.0,
        "near_ground": states.position[:, 2] < ground,
    }
    if states.vbat is not None and np.all(np.isfinite(states.vbat)):
        lo, hi = float(np.min(states.vbat)), float(np.max(states.vbat))
        drained = hi - lo > MIN_VBAT_DROP * abs(float(np.mean(states.vbat)))
        masks["low_battery"] = states.vbat <= lo + 0.2 * (hi - lo) if drained else \
            np.zeros(len(states.t), bool)
    return masks


def by_regime(scaled: list[np.ndarray], masks: list[dict[str, np.ndarray]]) -> dict:
    """Share of the total squared gap and of the samples in each regime."""
    total = sum(float(np.sum(e ** 2)) for e in scaled) or 1.0
    count = sum(len(e) for e in scaled)
    out = {}
    for name in ("hover", "climb", "descent", "fast_forward", "aggressive_rotation",
                 "near_ground", "low_battery"):
        parts = [(e[m[name]], m[name]) for e, m in zip(scaled, masks) if name in m]
        if not parts:
            continue
        energy = sum(float(np.sum(e ** 2)) for e, _ in parts)
        n = sum(int(m.sum()) for _, m in parts)
        out[name] = {"share": energy / total, "samples": n / max(count, 1),
                     "mean_gap": energy / max(n, 1) / scaled[0].shape[1] if n else 0.0}
    return out


def by_band(scaled: list[np.ndarray], dt: float) -> dict:
    """Share of the residual power in each frequency band (Welch, all channels together)."""
    power = {f"{lo:g}-{hi:g} Hz": 0.0 for lo, hi in BANDS_HZ}
    for e in scaled:
        if len(e) < 16:
            continue
        freq, psd = welch(e, fs=1.0 / dt, axis=0, nperseg=min(256, len(e)))
        total = psd.sum(axis=1)
        for lo, hi in BANDS_HZ:
            power[f"{lo:g}-{hi:g} Hz"] += float(total[(freq >= lo) & (freq < hi)].sum())
    whole = sum(power.values()) or 1.0
    return {band: value / whole for band, value in power.items()}


def kstep_errors(flights: list[FlightStates], params: VehicleParams, effects: list, *,
                 node_every_s: float = 0.1, max_nodes: int = 120, rtol: float = 1e-4,
                 atol: float = 1e-6) -> dict:
    """RMS position (m) and attitude (rad) error at each horizon in :data:`HORIZONS_S`.

    Uses :func:`quadsim.sim.engines.simulate` (analytic engine), one batch holding the shooting
    nodes of all flights (at most ``max_nodes``, evenly spread), with the measured rotor
    speeds held over each log step. Effects with rotor dynamics are left out (the rotor
    speeds are measured, not commanded)."""
    from ..sim.engines import simulate

    effects = [e for e in effects if rate_owner([e]) is None]
    dt = float(flights[0].t[1] - flights[0].t[0])
    steps = {h: max(1, round(h / dt)) for h in HORIZONS_S}
    horizon = max(steps.values())
    picks = []
    for f, states in enumerate(flights):
        nodes = np.arange(0, len(states.t) - horizon - 1, max(1, round(node_every_s / dt)))
        picks += [(f, int(n)) for n in nodes]
    empty = {f"{h:g}": {"position_rms_m": None, "attitude_rms_rad": None} for h in HORIZONS_S}
    if not picks:
        return empty
    picks = [picks[i] for i in np.unique(np.linspace(0, len(picks) - 1, max_nodes).astype(int))]

    def gather(name, offset=0):
        return np.stack([getattr(flights[f], name)[n + offset] for f, n in picks])

    series = np.stack([flights[f].rotor_speed[n:n + horizon] for f, n in picks])
    initial = {k: gather(k) for k in ("position", "velocity", "quat", "body_rate", "rotor_speed")}
    try:
        traj = simulate(params, engine="analytic", initial=initial, rotor_speed_series=series,
                        duration=horizon * dt, control_period=dt,
                        effects=EffectSet(tuple(effects)), rtol=rtol, atol=atol)
    except QuadsimError:
        return empty  # a diverging open-loop run cannot be scored at these horizons
    out = {}
    for h, k in steps.items():
        dp = np.linalg.norm(traj.position[:, k] - gather("position", k), axis=1)
        dq = quat_multiply(quat_conjugate(gather("quat", k)), traj.quat[:, k])
        angle = 2 * np.arccos(np.clip(np.abs(dq[:, 0]), 0, 1))
        out[f"{h:g}"] = {"position_rms_m": float(np.sqrt(np.mean(dp ** 2))),
                         "attitude_rms_rad": float(np.sqrt(np.mean(angle ** 2)))}
    return out
