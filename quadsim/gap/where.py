"""Where and when the gap lies, and whether a named effect holds across regimes: by channel,
flight regime, frequency band, and k-step prediction error; a named effect's value
checked on halves of the data (parameter consistency).

The where-functions (:func:`where`, :func:`by_regime`, :func:`by_band`) take residuals
already divided by the per-channel noise scale (so channels add), and return plain dicts
ready for JSON.

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

Parameter consistency
---------------------
A named effect must have *one* value in every regime it was fitted on.

A real effect has one value (a payload weighs the same slow and fast, a weak rotor is weak at
every speed). A library effect standing in for something outside the library needs different
values in different regimes: e.g. a thrust gain that grows with airspeed (translational lift)
is fitted as a linear thrust-curve term, large in fast flight and small near hover. The
guard refits the named candidate (its own parameters, started at the pooled fit) on two
halves of the data and compares:

* ``airspeed``: samples below / above the median in-plane ground speed |v_xy| (m/s) of all
  flights (aerodynamic effects the library lacks grow with it);
* ``rotor_speed``: samples below / above the median mean rotor speed (rad/s) (effects that
  depend on thrust or on Omega in a way the candidate does not).

A parameter is *inconsistent* on a split when the two values differ by more than their
combined 95 % interval, sqrt(ci_a^2 + ci_b^2) (statistically different), **and** by more
than :data:`MATERIAL` times the larger of the two magnitudes (materially different: a real
effect fitted on independent data or with a slightly wrong floor moves by a few %, not by
half its value). Only parameters that the pooled fit identified and found significant are
judged, and only on a half where the refit identifies them too (CI < half the range); a
parameter too weakly excited in one half cannot disagree.

A parameter whose halves differ beyond their combined interval but by less than
:data:`MATERIAL` *shifts* with the regime: the name stands, marked ``tentative`` (field
``verdict.tentative``, a note and a sentence in the answer): it
describes how the vehicle behaved over the flown range, but the value depends on airspeed or
rotor speed, so it may stand in for an effect outside the library (a thrust gain growing with
airspeed reads as a small thrust-curve term over a narrow speed range); flights over a wider
range of speeds tell.

If any judged parameter is inconsistent, the verdict is not a confident name: outcome
``unexplained``, and the candidate is reported as a *partial explanation*
(``verdict.partial``: name, share of the held-out gap it explains, parameters, and the
split values) with the words "explains N % but needs <p> = a in slow flight and b in fast
flight: a stand-in for an effect outside the library". The test uses only the data and
the candidate's own fit; nothing in it names an effect.

Units: parameter values and CIs in the parameter's own unit (``verdict.units``); split
thresholds in m/s (airspeed) and rad/s (rotor speed).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import welch

from ..core.errors import ModelError, QuadsimError
from ..core.frames import quat_conjugate, quat_multiply
from ..effects.base import EffectSet
from ..vehicle.params import VehicleParams
from .fitting import Candidate, fit_candidate, residuals
from .residual import FlightStates
from .rotor_channel import rate_owner

__all__ = ["BANDS_HZ", "HORIZONS_S", "MATERIAL", "MIN_SAMPLES", "SPLITS", "by_band",
           "by_regime", "check", "inconsistent_note", "kstep_errors", "partial_text",
           "regime_masks", "scaled_residuals", "split_masks", "standing", "tentative_note",
           "tentative_text", "where"]

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


# --- parameter consistency (module doc) ---------------------------------------------------------

#: relative difference (of the larger magnitude) above which two values are materially
#: different. 0.5: the two halves ask for values a factor >= 2 apart.
MATERIAL = 0.5
#: a half with fewer samples (after decimation) is not fitted.
MIN_SAMPLES = 200
SPLITS = ("airspeed", "rotor_speed")
_LABELS = {"airspeed": ("slow flight", "fast flight"),
           "rotor_speed": ("low rotor speed", "high rotor speed")}


def split_masks(flights: list[FlightStates]) -> dict[str, tuple[float, list[np.ndarray]]]:
    """Per split: (threshold, per-flight boolean masks of the *upper* half)."""
    speed = [np.linalg.norm(f.velocity[:, :2], axis=1) for f in flights]
    rotor = [np.mean(f.rotor_speed, axis=1) for f in flights]
    out = {}
    for name, values in zip(SPLITS, (speed, rotor)):
        threshold = float(np.median(np.concatenate(values)))
        out[name] = (threshold, [v > threshold for v in values])
    return out


def _fit_half(candidate, parts: list, *, params, sigma, rotor, start):
    """``candidate`` refitted on ``parts`` (the half's samples of each flight) from
    ``start``; None when the half is too small or the fit fails."""
    parts = [p for p in parts if len(p.t) > 10]
    if sum(len(p.t) for p in parts) < MIN_SAMPLES:
        return None
    try:
        return fit_candidate(candidate, parts, params, sigma, rotor_channel=rotor, start=start)
    except (ModelError, ValueError, np.linalg.LinAlgError):
        return None


def check(candidate: Candidate, theta: np.ndarray, judged: list[str],
          flights: list[FlightStates], *, params, sigma: np.ndarray, rotor: bool) -> dict:
    """Refit ``candidate`` (pooled values ``theta``) on each split's halves of ``flights``
    under ``params`` with noise scale ``sigma`` (rotor channels when ``rotor``); judge the
    parameters named in ``judged``.

    Returns ``{"consistent": bool, "splits": {split: {"threshold", "unit", "params": {p:
    {"low", "high", "ci_low", "ci_high", "consistent"}}}}, "inconsistent": [text, ...]}``."""
    names = candidate.parameter_names
    out: dict = {"consistent": True, "splits": {}, "inconsistent": [], "shifted": []}
    for split, (threshold, masks) in split_masks(flights).items():
        low, high = (_fit_half(candidate, [f.take(np.nonzero(m if upper else ~m)[0])
                                           for f, m in zip(flights, masks)],
                               params=params, sigma=sigma, rotor=rotor, start=theta)
                     for upper in (False, True))
        if low is None or high is None:
            continue
        entry = {"threshold": threshold, "unit": "m/s" if split == "airspeed" else "rad/s",
                 "params": {}}
        for k, p in enumerate(names):
            if p not in judged:
                continue
            a, b = float(low.theta[k]), float(high.theta[k])
            ca, cb = 1.96 * float(low.stderr[k]), 1.96 * float(high.stderr[k])
            both = bool(low.identifiable[k] and high.identifiable[k])
            diff = abs(a - b)
            differs = both and diff > np.hypot(ca, cb)
            ok = not (differs and diff > MATERIAL * max(abs(a), abs(b)))
            entry["params"][p] = {"low": a, "high": b, "ci_low": ca, "ci_high": cb,
                                  "consistent": ok}
            lo_label, hi_label = _LABELS[split]
            text = (f"{p} = {a:.3g} ± {ca:.2g} in {lo_label} and {b:.3g} ± {cb:.2g} in "
                    f"{hi_label} (split at {threshold:.3g} {entry['unit']})")
            if not ok:
                out["consistent"] = False
                out["inconsistent"].append(text)
            elif differs:
                out["shifted"].append(text)
        out["splits"][split] = entry
    return out


def standing(result: dict) -> str:
    """What ``result`` (:func:`check`) does to a name: ``"stands"`` (one value in every
    regime), ``"shifted"`` (a value moves beyond its interval by less than
    :data:`MATERIAL`: the name stands, tentative) or ``"inconsistent"`` (beyond
    :data:`MATERIAL`: ``unexplained``, a partial explanation)."""
    if not result["consistent"]:
        return "inconsistent"
    return "shifted" if result["shifted"] else "stands"


def partial_text(name: str, reduction: float, result: dict) -> str:
    """The answer for an inconsistent name: a partial explanation."""
    return (f"Unexplained: {name} explains {100 * reduction:.0f} % of the held-out gap but "
            f"needs different values in different regimes ({'; '.join(result['inconsistent'])})"
            f": a stand-in for an effect outside the library (or several effects), not a "
            f"cause. It is given as a partial explanation only.")


def inconsistent_note(name: str, result: dict) -> str:
    """The result's note for an inconsistent name."""
    return (f"{name} not named: its parameters are inconsistent between regimes ("
            + "; ".join(result["inconsistent"]) + ")")


def tentative_text(result: dict) -> str:
    """The sentence appended to the answer of a shifted name."""
    return (" Tentative: its value shifts with the regime (" + "; ".join(result["shifted"])
            + "), so it may stand in for an airspeed- or speed-dependent effect outside the "
            "library; flights over a wider range of speeds would tell.")


def tentative_note(result: dict) -> str:
    """The result's note for a shifted name."""
    return ("tentative name: the fitted value shifts with the regime ("
            + "; ".join(result["shifted"]) + ")")
