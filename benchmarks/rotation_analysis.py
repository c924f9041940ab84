"""Why the measured rotor speeds over-predict a real Crazyflie's roll and pitch acceleration.

Tests the candidate mechanisms of issue 45 against each other on the logs' own evidence. Per
log and per body axis (roll x, pitch y) it forms

* the torque the measured rotor speeds predict, ``tau = sum_i (r_i x a_i) b Omega_i^2`` (N m,
  the parameter set's hubs ``r_i``, axes ``a_i`` and thrust factor ``b``);
* the moment the body shows, ``M = J domega/dt + omega x J omega`` (N m; ``domega/dt`` by
  central differences of the logged body rate);
* the blade-flapping regressor ``f = sum_i Omega_i (v_y, -v_x)`` (body-frame velocity,
  (rad/s)(m/s); :mod:`quadsim.effects.blade_flapping` with ``a_i = z``), the aerodynamic moment
  that balances the rotors' torque in translation;
* an instrument for ``tau``: the same torque of the commanded speeds (motor map and its lag),
  whose noise is independent of the ESC's speed estimate.

All four are low-passed alike (zero-phase 4th-order Butterworth at ``LOWPASS_HZ``: the
benchmark's own zero-phase filters are at 18-20 Hz, and a filter applied alike to input and
output leaves their transfer unchanged) and resampled to ``RATE_HZ``.

Evidence
    :func:`band_transfer` -- the two-input frequency response ``M = H_tau tau + H_f f`` per band
    (Welch cross-spectra summed over the band's bins), with the multiple coherence;
    :func:`z_transfer` -- the same for the collective channel, ``b sum Omega^2 -> m a_z``
    (accelerometer), which has no inertia in it: a thrust lag (inflow dynamics) or a delayed or
    filtered speed estimate would show there too;
    :func:`low_band_balance` -- below 2 Hz, how much of the torque the body does not show the
    flapping moment explains, per axis and with a CoM-offset lever beside it
    (:func:`low_band_common`: one coefficient for both axes); :func:`windowed_gain` -- the gain
    a 0.5 s open-loop prediction needs (the benchmark's horizon), and
    :func:`windowed_heldout` -- that balance fitted on the training logs, scored on held-out
    ones against holding the rate.

Candidates, each fitted in the band where the rotors drive the body (``BAND_HZ``, band-passed
time series, flapping as co-regressor; the nonlinear parameter on a grid, the rest by least
squares; :func:`fit_candidate`)
    ``scale``   ``M = g tau(t - d)``: an inertia or torque-arm scale, a pure delay;
    ``lag``     ``M = g L_tau[tau]``, ``L`` a first-order lag: inflow dynamics between Omega and
                thrust, an ESC speed estimate that leads the true speed, a gyro filter;
    ``damping`` ``M = g tau - k omega``: aerodynamic rate damping;
    ``iv``      ``scale`` by instrumental variables: if rotor-speed noise (errors in variables)
                made the gain small, the instrumented gain is larger.

The gain ``g`` of every candidate reads as ``J_model / J_true`` where the rest is right.
Held out: each candidate fitted on the training logs predicts the band-passed moment of the
held-out logs (R^2).

Usage::

    python -m benchmarks.rotation_analysis --model models/nanodrone_cf21bl.toml \\
        --train ../shared/data/nanodrone_cf21bl/train/*_run[123].csv.gz \\
        --heldout ../shared/data/nanodrone_cf21bl/train/*_run4.csv.gz --json rot.json \
        [--effects-file IN.toml --write-effects OUT.toml] [--mechanisms also|only]

With ``--mechanisms`` it tests, below 2 Hz and beside the flapping, the mechanisms of
:data:`MECHANISMS` (airframe drag at a centre of pressure, the rear rotors' wake, per-rotor
inflow, the measured horizontal force on a lever, the advancing-blade moment, a flapping lag)
and the state features of :data:`FEATURES`, per log, pooled and held out
(:func:`analyse_mechanisms`); ``only`` skips the rest.

With ``--write-effects`` it writes the effect file ``--effects-file`` plus ``blade_flapping``
with ``roll`` and ``pitch`` from :func:`low_band_pooled` on the ``--train`` logs only, each
with its unit and source (this command and the logs); an effect file that already holds
``blade_flapping`` is refused.

Results and their reading: docs/nanodrone.md, "Why the rotor speeds over-predict roll and pitch";
the tables as measured: benchmarks/HISTORY.md, "Rotation: what the logs say".
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from quadsim.core.errors import InputError, QuadsimWarning, run_cli  # noqa: E402
from quadsim.core.files import atomic_write_text  # noqa: E402
from quadsim.core.frames import rotate_inverse  # noqa: E402
from quadsim.logs.flightlog import FlightLog, load_log  # noqa: E402
from quadsim.vehicle.params import VehicleParams, load_params  # noqa: E402

#: analysis rate (Hz): the benchmark's; the 500 Hz logs are low-passed and resampled to it
RATE_HZ = 100.0
#: common zero-phase low-pass (Hz), just above the benchmark's own 18-20 Hz filters
LOWPASS_HZ = 20.0
#: the band where the rotors drive the body (Hz): above ~3 Hz the flapping moment (a velocity
#: effect) is small against the torque; below 16 Hz the benchmark's 18 Hz filter leaves > 0.9
BAND_HZ = (4.0, 16.0)
#: bands of the frequency-response table (Hz)
BANDS_HZ = ((0.3, 1.0), (1.0, 2.0), (2.0, 4.0), (4.0, 8.0), (8.0, 12.0), (12.0, 16.0))
#: Welch segment (samples at RATE_HZ): 2.56 s, 0.39 Hz bins
SEGMENT = 256
#: candidate grids: delay d (s), lag time constant (s), damping is linear (no grid)
DELAYS_S = tuple(np.round(np.arange(-0.030, 0.0301, 0.0025), 4))
LAGS_S = (0.0, 0.0025, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.06, 0.08)
CANDIDATES = ("scale", "lag", "damping", "iv")
AXES = ("roll", "pitch")


@dataclass(frozen=True)
class Mechanism:
    """The regressors of one candidate physical mechanism of the low-band moment (one log).

    name: the family (:data:`MECHANISMS`, or ``feature:<name>`` for the exploratory state
    features of :func:`state_features`); labels: one per column; columns (N, 2, k): per sample,
    per axis (roll, pitch), per column, in the unit that makes the fitted coefficient the
    physical parameter of :data:`MECHANISMS` (the aerodynamic moment is ``sum_j beta_j
    columns[..., j]``, N m)."""

    name: str
    labels: tuple[str, ...]
    columns: np.ndarray


@dataclass(frozen=True)
class RotationSignals:
    """One log's rotation signals at ``RATE_HZ`` (N samples; columns roll, pitch).

    torque (N, 2) N m predicted by the measured rotor speeds; moment (N, 2) N m shown by the
    body; flapping (N, 2) (rad/s)(m/s); rate (N, 2) rad/s; instrument (N, 2) N m of the
    commanded speeds or None; thrust (N,) N = b sum Omega^2; force_z (N,) N = m a_z or None.
    """

    name: str
    torque: np.ndarray
    moment: np.ndarray
    flapping: np.ndarray
    rate: np.ndarray
    instrument: np.ndarray | None
    thrust: np.ndarray
    force_z: np.ndarray | None
    mechanisms: tuple[Mechanism, ...] = ()


@dataclass(frozen=True)
class BandResponse:
    """The response of the moment to the predicted torque in one band: gain (1) and phase
    (deg) of ``H_tau``, the flapping gain ``H_f`` (N m per (rad/s)(m/s)) and its phase, and the
    multiple coherence (1) of (torque, flapping) -> moment."""

    band_hz: tuple[float, float]
    gain: float
    phase_deg: float
    flap_gain: float
    flap_phase_deg: float
    coherence: float


@dataclass(frozen=True)
class CandidateFit:
    """One candidate fitted on some logs in ``BAND_HZ``: gain g (1) with its 95 % interval, the
    nonlinear parameter (``scale``: delay s; ``lag``: time constant s; ``damping``: k N m s/rad;
    ``iv``: delay s) with its interval, the flapping coefficient (N m per (rad/s)(m/s)) and R^2
    of the band-passed moment on the fitted logs."""

    candidate: str
    gain: float
    gain_ci: float
    parameter: float
    parameter_ci: float
    flapping: float
    r2: float


def _resample(t: np.ndarray, x: np.ndarray, grid: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(grid, t, c) for c in np.atleast_2d(x.T)], axis=-1)


#: candidate mechanisms of the low-band moment the flapping leaves (issue 45); the physics and
#: the unit of each coefficient: :func:`mechanism_columns`
MECHANISMS = ("body_drag", "wake_mu", "wake_mu2", "inflow", "inflow_split", "force_lever",
              "rotor_scale", "hub_roll", "flapping_lag", "air_field")
#: exploratory state features (:func:`state_features`), each one column for both axes
FEATURES = ("v_x", "v_y", "v_z", "|v|v_x", "|v|v_y", "v_z|v_z|", "w_x", "w_y", "w_z", "sf_x",
            "sf_y", "sf_z", "roll_angle", "pitch_angle", "thrust", "torque_x", "torque_y",
            "yaw_torque", "lin_x", "lin_y", "SOmega v_x", "SOmega v_y", "sOmega v_x",
            "sOmega v_y", "|v_h|", "const")


def mechanism_columns(params: VehicleParams, omega: np.ndarray, v_body: np.ndarray,
                      body_rate: np.ndarray, specific_force: np.ndarray | None
                      ) -> list[Mechanism]:
    """Regressors (raw rate, before filtering) of each mechanism of :data:`MECHANISMS`.

    Inputs: rotor speeds ``omega`` (N, R) rad/s (magnitudes), body-frame velocity ``v_body``
    (N, 3) m/s, body rate (N, 3) rad/s, specific force (N, 3) m/s^2 body or None. ``b`` the
    thrust factor, ``r_i``/``a_i`` hubs and axes, ``R`` the rotor radius (0.0275 m when the set
    has none: it only scales the coefficient), ``s_i`` +1 ccw / -1 cw. Columns give the moment
    (N m) per unit of the coefficient:

    * ``body_drag``: airframe drag ``-C |v| v`` (C in kg/m) acting at a centre of pressure off
      the CoM: lever h above it gives roll ``h C |v| v_y``, pitch ``-h C |v| v_x`` (column 1,
      coefficient hC in kg); a horizontal offset of the centre of pressure of the vertical drag
      gives ``v_z |v_z|`` on either axis (column 2, kg).
    * ``wake_mu`` / ``wake_mu2``: the rear rotors in the front rotors' wake lose thrust,
      ``Delta T_i = k b Omega_i^2 w_i mu_i^p`` (p = 1, 2) with ``mu_i = |v_h| / (Omega_i R)``
      and ``w_i = max(0, -r_i . u) / |r_i|`` (u the direction of the horizontal body velocity:
      1 for the rotor straight behind, 0 for the front half); moment ``sum_i (r_i x a_i)
      Delta T_i``; k dimensionless (negative = loss).
    * ``inflow``: each rotor's own axial inflow, ``T_i = b Omega_i^2 (1 - k w_i / (Omega_i
      R))`` with ``w_i = (v + omega x r_i) . a_i`` (translation and the rotation's own
      velocity at the hub): moment ``-k sum_i (r_i x a_i) b Omega_i w_i / R``, k dimensionless
      (positive for a rotor that loses thrust when it climbs); a rate damping ``~ Omega omega``
      and a differential thrust in vertical flight. ``inflow_split``: the translational and the
      rotational part with a k each.
    * ``force_lever``: the horizontal aerodynamic force the accelerometer measures, ``m (sf_x,
      sf_y)``, acting a height h above the CoM (rotor plane above it: h > 0): roll ``-h m
      sf_y``, pitch ``h m sf_x``; h in m. (The rotor-drag part, ``~ sum Omega v``, has the
      flapping regressor's shape: only the rest of the force can tell h.) Absent without
      ``specific_force``.
    * ``rotor_scale``: a thrust-factor error per rotor, ``T_i = (1 + delta_i) b Omega_i^2``,
      with the mean of the deltas left out (the collective thrust factor is identified from
      the vertical channel; an equal delta would be the low-band torque gain itself): columns
      ``(r_i x a_i) b Omega_i^2`` less their mean over the rotors; delta_i dimensionless.
    * ``hub_roll``: each rotor's advancing/retreating-blade moment about the flight direction,
      spin-signed: ``(sum_i s_i Omega_i) (v_x, v_y)`` on (roll, pitch); kg m/rad.
    """
    b = params.thrust_factor
    radius = params.rotor_radius if params.rotor_radius > 0 else 0.0275
    r, a = params.rotor_positions, params.rotor_axes
    arms = np.cross(r, a)                                             # (R, 3) m per N
    spins = params.rotor_spins
    n = len(omega)
    speed = np.linalg.norm(v_body, axis=1)
    vh = v_body[:, :2]
    speed_h = np.linalg.norm(vh, axis=1)
    mechs = []
    drag = np.stack([np.column_stack([speed * v_body[:, 1], -speed * v_body[:, 0]]),
                     np.repeat((v_body[:, 2] * np.abs(v_body[:, 2]))[:, None], 2, axis=1)],
                    axis=-1)
    mechs.append(Mechanism("body_drag", ("|v| (v_y, -v_x)", "v_z |v_z|"), drag))
    u = vh / np.maximum(speed_h, 1e-6)[:, None]
    r_h = r[:, :2] / np.maximum(np.linalg.norm(r[:, :2], axis=1), 1e-9)[:, None]
    rear = np.maximum(0.0, -(u @ r_h.T))                              # (N, R)
    mu = speed_h[:, None] / np.maximum(omega, 1.0) / radius
    for name, power in (("wake_mu", 1), ("wake_mu2", 2)):
        dt = b * omega ** 2 * rear * mu ** power
        mechs.append(Mechanism(name, (f"rear rotors' thrust x mu^{power}",),
                               (dt @ arms)[:, :2, None]))
    w_trans = v_body @ a.T                                            # (N, R)
    w_rot = np.einsum("nrk,rk->nr", np.cross(body_rate[:, None, :], r[None, :, :]), a)
    parts = [-(b * omega * w / radius) @ arms for w in (w_trans, w_rot)]
    mechs.append(Mechanism("inflow", ("-b Omega_i w_i / R",),
                           (parts[0] + parts[1])[:, :2, None]))
    mechs.append(Mechanism("inflow_split", ("translation", "rotation"),
                           np.stack([parts[0][:, :2], parts[1][:, :2]], axis=-1)))
    if specific_force is not None:
        force = params.mass * specific_force
        mechs.append(Mechanism("force_lever", ("m (-sf_y, sf_x)",),
                               np.column_stack([-force[:, 1], force[:, 0]])[:, :, None]))
    quad = arms[None, :, :2] * (b * omega ** 2)[:, :, None]           # (N, R, 2)
    quad = quad - quad.mean(axis=1, keepdims=True)
    mechs.append(Mechanism("rotor_scale", tuple(f"rotor {k + 1}" for k in range(len(r))),
                           np.transpose(quad, (0, 2, 1))))
    spin_sum = omega @ spins
    mechs.append(Mechanism("hub_roll", ("(sum s_i Omega_i) (v_x, v_y)",),
                           (spin_sum[:, None] * vh)[:, :, None]))
    assert all(m.columns.shape[:2] == (n, 2) for m in mechs)
    return mechs


def air_field_columns(omega: np.ndarray, quat: np.ndarray, position: np.ndarray) -> Mechanism:
    """``air_field``: the flight arena's own air (recirculated downwash), a wind linear in
    position, ``w(p) = w0 + G (p - mean p)`` (world x, y components), seen by the flapping
    moment as ``c sum Omega (w_y, -w_x)`` in the body frame with c the flapping coefficient:
    columns ``sum Omega (e_y, -e_x)`` of each world axis ``k`` (x, y; ``e = R^T e_k``) times
    (1, p_x, p_y, p_z); coefficients ``-c w0_k`` (kg m/rad x m/s) and ``-c G_kj`` (kg m/rad x
    1/s). Inputs: rotor speeds (N, R) rad/s, attitude (N, 4) wxyz, position (N, 3) m world."""
    total = omega.sum(axis=1)
    pos = position - position.mean(axis=0)
    cols = []
    for k in range(2):
        e = np.zeros((len(omega), 3))
        e[:, k] = 1.0
        eb = rotate_inverse(quat, e)
        base = np.column_stack([total * eb[:, 1], -total * eb[:, 0]])
        for g in (np.ones(len(omega)), pos[:, 0], pos[:, 1], pos[:, 2]):
            cols.append(base * g[:, None])
    labels = tuple(f"w{a}{g}" for a in "xy" for g in ("", "*x", "*y", "*z"))
    return Mechanism("air_field", labels, np.stack(cols, axis=-1))


def state_features(params: VehicleParams, omega: np.ndarray, v_body: np.ndarray,
                   body_rate: np.ndarray, specific_force: np.ndarray | None,
                   quat: np.ndarray) -> list[Mechanism]:
    """The exploratory features of :data:`FEATURES` (raw rate), each a ``feature:<name>``
    :class:`Mechanism` with the same single column on both axes: body velocity, ``|v| v``,
    ``v_z |v_z|``, body rate, specific force (m/s^2; zeros without it), roll and pitch angle
    (rad), thrust ``b sum Omega^2`` (N), the rotor torque (N m), the yaw-torque pattern ``b sum
    s_i Omega_i^2`` (N), the linear-in-speed torque patterns ``sum (r_i x a_i) Omega_i`` (m
    rad/s: a thrust curve's linear term), ``sum Omega (v_x, v_y)`` and ``sum s_i Omega (v_x,
    v_y)`` ((rad/s)(m/s)), the horizontal speed (m/s) and a constant (a trim moment: a CoM
    offset or thrust mismatch at constant thrust; zero below 2 Hz, where each log's mean is
    removed). Coefficients are in the feature's
    unit (N m per unit): exploration, not a model."""
    b = params.thrust_factor
    arms = np.cross(params.rotor_positions, params.rotor_axes)
    speed = np.linalg.norm(v_body, axis=1)
    sf = np.zeros_like(v_body) if specific_force is None else specific_force
    qw, qx, qy, qz = quat.T
    roll = np.arctan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx ** 2 + qy ** 2))
    pitch = np.arcsin(np.clip(2 * (qw * qy - qz * qx), -1, 1))
    torque = b * (omega ** 2) @ arms
    lin = omega @ arms
    s_all, s_spin = omega.sum(axis=1), omega @ params.rotor_spins
    values = (v_body[:, 0], v_body[:, 1], v_body[:, 2], speed * v_body[:, 0],
              speed * v_body[:, 1], v_body[:, 2] * np.abs(v_body[:, 2]), body_rate[:, 0],
              body_rate[:, 1], body_rate[:, 2], sf[:, 0], sf[:, 1], sf[:, 2], roll, pitch,
              b * (omega ** 2).sum(axis=1), torque[:, 0], torque[:, 1],
              b * (omega ** 2) @ params.rotor_spins, lin[:, 0], lin[:, 1],
              s_all * v_body[:, 0], s_all * v_body[:, 1], s_spin * v_body[:, 0],
              s_spin * v_body[:, 1], np.linalg.norm(v_body[:, :2], axis=1), np.ones(len(omega)))
    return [Mechanism(f"feature:{name}", (name,), np.repeat(x[:, None, None], 2, axis=1))
            for name, x in zip(FEATURES, values)]


def rotation_signals(log: FlightLog, params: VehicleParams) -> RotationSignals:
    """:class:`RotationSignals` of one log (needs rotor speeds, velocity and body rate).

    Raises InputError when the log lacks them or has another rotor count than ``params``."""
    name = Path(str(log.path)).name.split(".")[0] if log.path else "log"
    if log.rotor_speed is None or log.body_rate is None or log.velocity is None:
        raise InputError(f"{log.path}: rotor_1..N, wx..wz, vx..vz: needed")
    if log.rotor_speed.shape[1] != params.rotor_count:
        raise InputError(f"{log.path}: rotor_1..N: {log.rotor_speed.shape[1]} rotors, the "
                         f"model has {params.rotor_count}")
    t = np.asarray(log.t, float)
    fs_raw = 1.0 / float(np.median(np.diff(t)))
    sos = signal.butter(4, LOWPASS_HZ, fs=fs_raw, output="sos")
    lowpass = lambda x: signal.sosfiltfilt(sos, x, axis=0)           # noqa: E731
    omega = np.abs(np.asarray(log.rotor_speed, float))
    arms = np.cross(params.rotor_positions, params.rotor_axes)        # (R, 3) m per N
    b = params.thrust_factor
    torque = b * (omega ** 2) @ arms
    v_body = rotate_inverse(np.asarray(log.quat, float), np.asarray(log.velocity, float))
    s = omega.sum(axis=1)
    flapping = np.column_stack([s * v_body[:, 1], -s * v_body[:, 0], np.zeros_like(s)])
    instrument = None
    mm = params.motor_map
    if log.rotor_command is not None and mm is not None:
        speed = mm.speed_at(np.asarray(log.rotor_command, float), log.vbat)
        if mm.time_constant > 0:
            a = np.exp(-1.0 / (fs_raw * mm.time_constant))
            speed = signal.lfilter([1 - a], [1, -a], speed - speed[0], axis=0) + speed[0]
        instrument = b * speed ** 2 @ arms
    grid = np.arange(t[0], t[-1], 1.0 / RATE_HZ)
    w = _resample(t, lowpass(np.asarray(log.body_rate, float)), grid)
    wdot = np.gradient(w, 1.0 / RATE_HZ, axis=0)
    inertia = params.inertia
    moment = wdot @ inertia.T + np.cross(w, w @ inertia.T)
    pick = lambda x: _resample(t, lowpass(x), grid)                   # noqa: E731
    force_z = None if log.accel is None else params.mass * pick(log.accel[:, 2:3])[:, 0]
    rate_raw = np.asarray(log.body_rate, float)
    accel = None if log.accel is None else np.asarray(log.accel, float)
    raw = [*mechanism_columns(params, omega, v_body, rate_raw, accel),
           *([] if log.position is None else [air_field_columns(
               omega, np.asarray(log.quat, float), np.asarray(log.position, float))]),
           *state_features(params, omega, v_body, rate_raw, accel,
                           np.asarray(log.quat, float))]
    mechanisms = tuple(
        Mechanism(m.name, m.labels, pick(m.columns.reshape(len(t), -1)).reshape(
            len(grid), 2, -1)) for m in raw)
    # flapping_lag: a first-order lag tau_f between the edgewise flow and the flapping moment
    # (wake skew, inflow) gives c L[f] ~ c (f - tau_f df/dt): the column df/dt, coefficient
    # -c tau_f (kg m s/rad)
    flap = pick(flapping)[:, :2]
    mechanisms = (*mechanisms, Mechanism(
        "flapping_lag", ("d/dt sum Omega (v_y, -v_x)",),
        np.gradient(flap, 1.0 / RATE_HZ, axis=0)[:, :, None]))
    return RotationSignals(
        name=name, torque=pick(torque)[:, :2], moment=moment[:, :2],
        flapping=pick(flapping)[:, :2], rate=w[:, :2],
        instrument=None if instrument is None else pick(instrument)[:, :2],
        thrust=pick(b * (omega ** 2).sum(axis=1, keepdims=True))[:, 0], force_z=force_z,
        mechanisms=mechanisms)


def _spectra(inputs: list[np.ndarray], output: np.ndarray):
    """Welch cross-spectral matrix of the inputs (F, n, n), input-output (F, n), output (F,)."""
    kw = {"fs": RATE_HZ, "nperseg": SEGMENT}
    x = [u - u.mean() for u in inputs]
    y = output - output.mean()
    f, syy = signal.welch(y, **kw)
    n = len(x)
    suu = np.zeros((len(f), n, n), complex)
    suy = np.zeros((len(f), n), complex)
    for i in range(n):
        for j in range(n):
            suu[:, i, j] = signal.csd(x[i], x[j], **kw)[1]
        suy[:, i] = signal.csd(x[i], y, **kw)[1]
    return f, suu, suy, syy


def band_transfer(inputs: list[np.ndarray], output: np.ndarray,
                  bands=BANDS_HZ) -> list[tuple[np.ndarray, float]]:
    """Multi-input frequency response per band: ``output = sum_k H_k inputs_k``, the spectra
    summed over the band's Welch bins (``H = Suu^-T Suy``, ``csd(u, y) = conj(U) Y``); returns
    per band (H (n,) complex, multiple coherence)."""
    f, suu, suy, syy = _spectra(inputs, output)
    out = []
    for lo, hi in bands:
        m = (f >= lo) & (f < hi)
        a, c = suu[m].sum(axis=0), suy[m].sum(axis=0)
        h = np.linalg.solve(a, c)
        coherence = float(np.real(np.conj(c) @ np.linalg.solve(a, c)) / syy[m].sum())
        out.append((h, coherence))
    return out


def axis_response(sig: RotationSignals, axis: int, bands=BANDS_HZ) -> list[BandResponse]:
    """:class:`BandResponse` per band of (torque, flapping) -> moment on one axis."""
    rows = []
    for band, (h, coherence) in zip(bands, band_transfer(
            [sig.torque[:, axis], sig.flapping[:, axis]], sig.moment[:, axis], bands)):
        rows.append(BandResponse(band, float(abs(h[0])), float(np.degrees(np.angle(h[0]))),
                                 float(abs(h[1])), float(np.degrees(np.angle(h[1]))),
                                 coherence))
    return rows


def _bandpass(x: np.ndarray) -> np.ndarray:
    sos = signal.butter(4, BAND_HZ, btype="bandpass", fs=RATE_HZ, output="sos")
    return signal.sosfiltfilt(sos, x, axis=0)


def delayed(x: np.ndarray, delay_s: float) -> np.ndarray:
    """``x(t - delay)`` by linear interpolation (edges held)."""
    n = np.arange(len(x), dtype=float)
    return np.interp(n - delay_s * RATE_HZ, n, x)


def lagged(x: np.ndarray, tau_s: float) -> np.ndarray:
    """``x`` through a first-order lag of time constant ``tau_s`` (s), started at rest at
    ``x[0]``; unchanged for ``tau_s <= 0``."""
    if tau_s <= 0:
        return x
    a = np.exp(-1.0 / (RATE_HZ * tau_s))
    return signal.lfilter([1 - a], [1, -a], x - x[0]) + x[0]


def _design(sig: RotationSignals, axis: int, candidate: str, parameter: float):
    """Band-passed (regressors, moment[, instruments]) of one log for one candidate at a grid
    value of its nonlinear parameter."""
    tau = sig.torque[:, axis]
    if candidate in ("scale", "iv"):
        tau = delayed(tau, parameter)
    elif candidate == "lag":
        tau = lagged(tau, parameter)
    cols = [tau, sig.flapping[:, axis]]
    if candidate == "damping":
        cols.append(-sig.rate[:, axis])
    x = _bandpass(np.column_stack(cols))
    y = _bandpass(sig.moment[:, axis])
    z = None
    if candidate == "iv":
        if sig.instrument is None:
            raise InputError(f"{sig.name}: cmd_1..N and a motor map: needed for the iv "
                             "candidate")
        z = _bandpass(np.column_stack([sig.instrument[:, axis], sig.flapping[:, axis]]))
    return x, y, z


def _solve(parts, candidate: str):
    x = np.vstack([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    if candidate == "iv":
        z = np.vstack([p[2] for p in parts])
        coef = np.linalg.solve(z.T @ x, z.T @ y)
    else:
        coef = np.linalg.lstsq(x, y, rcond=None)[0]
    r2 = 1.0 - float(np.var(y - x @ coef) / np.var(y))
    return coef, r2


def _fit_once(designs: dict, candidate: str, keep: list[np.ndarray] | None = None):
    """Best grid value, coefficients and R^2 over precomputed band-passed designs
    ``{value: [(x, y, z) per log]}``, on the rows ``keep`` of each log (all when None)."""
    best = None
    for value, parts in designs.items():
        if keep is not None:
            parts = [(x[k], y[k], None if z is None else z[k])
                     for (x, y, z), k in zip(parts, keep)]
        coef, r2 = _solve(parts, candidate)
        if best is None or r2 > best[2]:
            best = (value, coef, r2)
    return best


def fit_candidate(sigs: list[RotationSignals], axis: int, candidate: str, *,
                  blocks: int = 8) -> CandidateFit:
    """Fit one candidate on the logs' ``BAND_HZ`` band (grid value of the nonlinear parameter
    by the best R^2, the rest by least squares or, for ``iv``, instrumental variables); 95 %
    intervals by a delete-one-block jackknife over ``blocks`` contiguous blocks of every log's
    band-passed rows (the band-passed residual is correlated over tens of samples, so
    per-sample least-squares errors would be too small)."""
    grid = {"scale": DELAYS_S, "iv": DELAYS_S, "lag": LAGS_S, "damping": (0.0,)}[candidate]
    designs = {v: [_design(s, axis, candidate, v) for s in sigs] for v in grid}
    value, coef, r2 = _fit_once(designs, candidate)
    reps = []
    for k in range(blocks):
        keep = []
        for s in sigs:
            n = len(s.moment)
            mask = np.ones(n, bool)
            mask[k * n // blocks:(k + 1) * n // blocks] = False
            keep.append(mask)
        v, c, _ = _fit_once(designs, candidate, keep)
        reps.append((c[0], c[-1] if candidate == "damping" else v))
    reps = np.array(reps)
    spread = np.sqrt((blocks - 1) / blocks * ((reps - reps.mean(axis=0)) ** 2).sum(axis=0))
    parameter = float(coef[-1]) if candidate == "damping" else float(value)
    return CandidateFit(candidate, float(coef[0]), float(1.96 * spread[0]), parameter,
                        float(1.96 * spread[1]), float(coef[1]), r2)


def heldout_r2(fit: CandidateFit, sig: RotationSignals, axis: int) -> float:
    """R^2 of the band-passed moment of a held-out log predicted by a fitted candidate."""
    candidate = "scale" if fit.candidate == "iv" else fit.candidate
    x, y, _ = _design(sig, axis, candidate, 0.0 if candidate == "damping" else fit.parameter)
    coef = [fit.gain, fit.flapping] + ([fit.parameter] if candidate == "damping" else [])
    return 1.0 - float(np.var(y - x @ np.asarray(coef)) / np.var(y))


def _windows(sig: RotationSignals, axis: int, horizon: int):
    """(regressors (W, 2): integrated torque and flapping, N m s; target (W,): J delta-omega)
    over every window of ``horizon`` samples."""
    dt = 1.0 / RATE_HZ

    def wsum(x):
        c = np.concatenate([[0.0], np.cumsum(x)])
        return (c[horizon:] - c[:-horizon])[:-1] * dt

    x = np.column_stack([wsum(sig.torque[:, axis]), wsum(sig.flapping[:, axis])])
    return x, wsum(sig.moment[:, axis])


def windowed_heldout(train: list[RotationSignals], held: list[RotationSignals], axis: int,
                     horizon: int = 50) -> tuple[tuple[float, float], list[float]]:
    """The 0.5 s balance ``J delta-omega = g int tau + c int f`` fitted over every window of
    the training logs ((g, c)), and per held-out log the RMS error of its predicted rate change
    over the RMS of the rate change itself (holding the rate scores 1; below 1 beats it)."""
    parts = [_windows(s, axis, horizon) for s in train]
    coef = np.linalg.lstsq(np.vstack([p[0] for p in parts]),
                           np.concatenate([p[1] for p in parts]), rcond=None)[0]
    ratios = []
    for s in held:
        x, y = _windows(s, axis, horizon)
        ratios.append(float(np.sqrt(np.mean((y - x @ coef) ** 2)) / np.sqrt(np.mean(y ** 2))))
    return (float(coef[0]), float(coef[1])), ratios


def windowed_gain(sig: RotationSignals, axis: int, horizon: int = 50) -> tuple[float, float]:
    """What a 0.5 s open-loop prediction needs: the least-squares gain g (1) and flapping
    coefficient of ``J (omega(t+H) - omega(t)) = sum_{k<H} (g tau + c f) dt`` over every window
    of the log (the integrated moment balance, dominated by frequencies below ~2 Hz)."""
    dt = 1.0 / RATE_HZ

    def wsum(x):
        c = np.concatenate([[0.0], np.cumsum(x)])
        return (c[horizon:] - c[:-horizon])[:-1] * dt

    m = sig.moment[:, axis]
    # J delta-omega equals the integral of the moment (exactly, up to the gyroscopic term)
    target = np.concatenate([[0.0], np.cumsum(m)])
    target = (target[horizon:] - target[:-horizon])[:-1] * dt
    x = np.column_stack([wsum(sig.torque[:, axis]), wsum(sig.flapping[:, axis])])
    coef = np.linalg.lstsq(x, target, rcond=None)[0]
    return float(coef[0]), float(coef[1])


def low_band_balance(sig: RotationSignals, axis: int, cutoff_hz: float = 2.0) -> dict:
    """Below ``cutoff_hz``: RMS (N m) of the predicted torque and of the body's moment, and how
    much of their difference the flapping moment explains: ``tau - M = -c f + c0`` by least
    squares (c in N m per (rad/s)(m/s), R^2 of the difference); with a thrust term beside it
    (``+ a T``, the lever of a CoM offset, ``com_arm_mm`` = a in mm) the residual left."""
    sos = signal.butter(2, cutoff_hz, fs=RATE_HZ, output="sos")
    low = lambda x: signal.sosfiltfilt(sos, x - x.mean())            # noqa: E731
    tau, m, f = low(sig.torque[:, axis]), low(sig.moment[:, axis]), low(sig.flapping[:, axis])
    diff = tau - m
    x = np.column_stack([-f, np.ones_like(f)])
    coef = np.linalg.lstsq(x, diff, rcond=None)[0]
    r2 = 1.0 - float(np.var(diff - x @ coef) / np.var(diff))
    # a CoM offset from the frame's centre by r adds -r x (0, 0, T): a torque linear in thrust
    thrust = low(sig.thrust)
    xc = np.column_stack([-f, thrust, np.ones_like(f)])
    coef_c = np.linalg.lstsq(xc, diff, rcond=None)[0]
    return {"torque_rms": float(f"{np.std(tau):.3g}"), "moment_rms": float(f"{np.std(m):.3g}"),
            "flapping": float(f"{coef[0]:.3g}"), "balance_r2": round(r2, 3),
            "residual_rms": float(f"{np.std(diff - x @ coef):.3g}"),
            "com_arm_mm": round(1e3 * float(coef_c[1]), 2),
            "residual_rms_with_com": float(f"{np.std(diff - xc @ coef_c):.3g}")}


def low_band_common(sig: RotationSignals, cutoff_hz: float = 2.0) -> dict:
    """As :func:`low_band_balance` with one flapping coefficient for both axes (the library's
    ``blade_flapping``): the coefficient and the residual RMS (N m) per axis."""
    sos = signal.butter(2, cutoff_hz, fs=RATE_HZ, output="sos")
    low = lambda x: signal.sosfiltfilt(sos, x - x.mean())            # noqa: E731
    diff = [low(sig.torque[:, a]) - low(sig.moment[:, a]) for a in (0, 1)]
    flap = [low(sig.flapping[:, a]) for a in (0, 1)]
    x, y = np.concatenate(flap), np.concatenate(diff)
    c = -float(x @ y) / float(x @ x)
    return {"flapping": float(f"{c:.3g}"),
            "residual_rms": [float(f"{np.std(diff[a] + c * flap[a]):.3g}") for a in (0, 1)]}


def low_band_pooled(sigs: list[RotationSignals], axis: int, cutoff_hz: float = 2.0) -> dict:
    """One flapping coefficient for ``axis`` over several logs (the per-axis ``roll`` or
    ``pitch`` of :mod:`quadsim.effects.blade_flapping`, kg m/rad): the package's estimator
    (:func:`quadsim.identify.flapping.flapping_estimate`, the one ``identify --logs`` reports)
    on these signals: below ``cutoff_hz``, ``tau - M = -c f + c0_k`` by least squares over
    every log's samples together (each log ``k`` its own constant), as
    :func:`low_band_balance` per log; ``ci``: the 95 % half-width of a delete-one-log
    jackknife (nan below the estimator's 3 logs), ``per_log``: each log's own c,
    ``identified``/``why``: the estimator's acceptance."""
    from quadsim.identify.flapping import flapping_estimate, flapping_part

    parts = [flapping_part(s.name, s.torque[:, axis], s.moment[:, axis], s.flapping[:, axis],
                           RATE_HZ, cutoff_hz=cutoff_hz) for s in sigs]
    est = flapping_estimate(parts, AXES[axis])
    per_log = [flapping_estimate([p], AXES[axis]).value for p in parts]
    ci = 0.5 * (est.ci95[1] - est.ci95[0])
    return {"flapping": float(f"{est.value:.4g}"), "ci": float(f"{ci:.3g}"), "logs": len(parts),
            "per_log": [float(f"{c:.3g}") for c in per_log], "identified": est.identified,
            "why": est.why}


def _mechanism(sig: RotationSignals, name: str) -> Mechanism | None:
    return next((m for m in sig.mechanisms if m.name == name), None)


def _lowband_design(sig: RotationSignals, axis: int, names: tuple[str, ...],
                    cutoff_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Below ``cutoff_hz`` (zero-phase 2nd-order Butterworth, the log's mean removed as in
    :func:`low_band_balance`): regressors (flapping, then the columns of each mechanism in
    ``names``) and the aerodynamic moment the rotors fight, ``y = M - tau`` (N m)."""
    sos = signal.butter(2, cutoff_hz, fs=RATE_HZ, output="sos")
    low = lambda x: signal.sosfiltfilt(sos, x - x.mean(axis=0), axis=0)  # noqa: E731
    cols = [sig.flapping[:, axis:axis + 1]]
    for name in names:
        cols.append(_mechanism(sig, name).columns[:, axis, :])
    x = low(np.column_stack(cols))
    y = low(sig.moment[:, axis] - sig.torque[:, axis])
    return x - x.mean(axis=0), y - y.mean()


def needed_moment_rms(sig: RotationSignals, axis: int, horizon: int = 50) -> float:
    """The moment accuracy (N m RMS) a ``horizon``-sample open-loop rate prediction needs to
    beat holding the rate: RMS of ``J delta-omega`` over every window divided by the window's
    duration (an error of that size, held over the window, equals holding the rate)."""
    x = np.concatenate([[0.0], np.cumsum(sig.moment[:, axis])]) / RATE_HZ
    jdw = x[horizon:] - x[:-horizon]
    return float(np.sqrt(np.mean(jdw ** 2)) / (horizon / RATE_HZ))


def _windows_with(sig: RotationSignals, axis: int, names: tuple[str, ...], horizon: int):
    """As :func:`_windows` with each mechanism's columns integrated beside torque and
    flapping."""
    x, y = _windows(sig, axis, horizon)
    dt = 1.0 / RATE_HZ
    extra = []
    for name in names:
        cols = _mechanism(sig, name).columns[:, axis, :]
        c = np.vstack([np.zeros((1, cols.shape[1])), np.cumsum(cols, axis=0)])
        extra.append((c[horizon:] - c[:-horizon])[:-1] * dt)
    return (np.column_stack([x, *extra]) if extra else x), y


def mechanism_balance(train: list[RotationSignals], held: list[RotationSignals], axis: int,
                      names: tuple[str, ...], *, cutoff_hz: float = 2.0,
                      horizon: int = 50) -> dict:
    """How much of the low-band moment the flapping leaves the mechanisms ``names`` explain.

    ``M - tau = c f + sum_j beta_j X_j`` below ``cutoff_hz`` (:func:`_lowband_design`):

    * ``per_log``: fitted on each log alone (training and held out): ``coef`` (c, then the
      betas in the columns' units), ``residual_rms`` (N m) and ``flapping_only_rms`` (the same
      fit without the mechanism), ``factor`` = their ratio (> 1: the mechanism helps);
    * ``pooled``: c and betas fitted on the training logs together, ``coef_ci`` the 95 %
      half-width of a delete-one-log jackknife; per held-out log the residual RMS of that
      fixed fit against the pooled flapping-only fit's and their ratio ``factor``;
    * ``windowed_0p5s``: the 0.5 s balance ``J delta-omega = g int tau + c int f + sum_j
      beta_j int X_j`` fitted over every window of the training logs, per held-out log the RMS
      error of the predicted rate change over that of holding the rate, with (``ratio``) and
      without (``flapping_only``) the mechanism (below 1 beats holding the rate);
      ``windowed_coef``: that fit's (g, c, betas).
    """
    def fit(parts):
        x = np.vstack([p[0] for p in parts])
        y = np.concatenate([p[1] for p in parts])
        return np.linalg.lstsq(x, y, rcond=None)[0]

    def rms(part, coef):
        return float(np.std(part[1] - part[0] @ coef))

    out = {"per_log": {}, "pooled": {}, "windowed_0p5s": {}}
    for s in [*train, *held]:
        full, flap = _lowband_design(s, axis, names, cutoff_hz), \
            _lowband_design(s, axis, (), cutoff_hz)
        coef = fit([full])
        r, r0 = rms(full, coef), rms(flap, fit([flap]))
        out["per_log"][s.name] = {"coef": [float(f"{c:.4g}") for c in coef],
                                  "residual_rms": float(f"{r:.3g}"),
                                  "flapping_only_rms": float(f"{r0:.3g}"),
                                  "factor": round(r0 / r, 3)}
    full = [_lowband_design(s, axis, names, cutoff_hz) for s in train]
    flap = [_lowband_design(s, axis, (), cutoff_hz) for s in train]
    coef, coef0 = fit(full), fit(flap)
    n = len(full)
    drops = np.array([fit([full[k] for k in range(n) if k != j]) for j in range(n)]) \
        if n > 1 else np.full((1, len(coef)), np.nan)
    ci = 1.96 * np.sqrt((n - 1) / n * ((drops - drops.mean(axis=0)) ** 2).sum(axis=0))
    out["pooled"] = {"coef": [float(f"{c:.4g}") for c in coef],
                     "coef_ci": [float(f"{c:.3g}") for c in ci], "heldout": {}}
    for s in held:
        r = rms(_lowband_design(s, axis, names, cutoff_hz), coef)
        r0 = rms(_lowband_design(s, axis, (), cutoff_hz), coef0)
        out["pooled"]["heldout"][s.name] = {
            "residual_rms": float(f"{r:.3g}"), "flapping_only_rms": float(f"{r0:.3g}"),
            "factor": round(r0 / r, 3),
            "needed_rms": float(f"{needed_moment_rms(s, axis, horizon):.3g}")}
    for label, use in (("ratio", names), ("flapping_only", ())):
        parts = [_windows_with(s, axis, use, horizon) for s in train]
        wcoef = fit(parts)
        if use:
            out["windowed_coef"] = [float(f"{c:.4g}") for c in wcoef]
        for s in held:
            x, y = _windows_with(s, axis, use, horizon)
            out["windowed_0p5s"].setdefault(s.name, {})[label] = round(
                float(np.sqrt(np.mean((y - x @ wcoef) ** 2)) / np.sqrt(np.mean(y ** 2))), 3)
    return out


def _best_addition(pool: list[str], chosen: list[str], design, score) -> tuple:
    """One greedy step: the name of ``pool`` not yet ``chosen`` whose least-squares fit on the
    stacked ``design((*chosen, name))`` parts ((x, y) per log) gives the smallest
    ``score(y, fitted)``; (name, score, coefficients)."""
    best = None
    for name in pool:
        if name in chosen:
            continue
        parts = design((*chosen, name))
        x = np.vstack([p[0] for p in parts])
        y = np.concatenate([p[1] for p in parts])
        coef = np.linalg.lstsq(x, y, rcond=None)[0]
        r = score(y, x @ coef)
        if best is None or r < best[1]:
            best = (name, r, coef)
    return best


def feature_selection(train: list[RotationSignals], held: list[RotationSignals], axis: int,
                      *, steps: int = 3, cutoff_hz: float = 2.0) -> list[dict]:
    """Greedy forward selection among the :data:`FEATURES` (beside the flapping regressor) on
    the training logs together, below ``cutoff_hz``: at each step the feature that lowers the
    pooled training residual most; per step the feature, the training residual RMS and the
    held-out factor per log (pooled flapping-only residual RMS over the residual RMS with the
    features chosen so far, all fitted on the training logs)."""
    chosen: list[str] = []
    pool = [f"feature:{name}" for name in FEATURES]
    rows = []
    for _ in range(steps):
        best = _best_addition(
            pool, chosen, lambda names: [_lowband_design(s, axis, names, cutoff_hz)
                                         for s in train],
            lambda y, fitted: float(np.std(y - fitted)))
        chosen.append(best[0])
        res = mechanism_balance(train, held, axis, tuple(chosen), cutoff_hz=cutoff_hz)
        rows.append({"feature": best[0].split(":", 1)[1], "train_rms": float(f"{best[1]:.3g}"),
                     "coef": res["pooled"]["coef"],
                     "heldout_factor": {k: v["factor"]
                                        for k, v in res["pooled"]["heldout"].items()},
                     "windowed_0p5s": res["windowed_0p5s"]})
    return rows


#: features the 0.5 s balance already holds (its gain on the integrated torque): left out of
#: :func:`windowed_selection`
TORQUE_FEATURES = ("torque_x", "torque_y", "lin_x", "lin_y")
#: delays of the flapping regressor behind the velocity (s) for :func:`flapping_timing`
FLAPPING_DELAYS_S = tuple(np.round(np.arange(-0.1, 0.2001, 0.01), 3))


def windowed_selection(train: list[RotationSignals], held: list[RotationSignals], axis: int,
                       *, steps: int = 3, horizon: int = 50) -> list[dict]:
    """Greedy forward selection of :data:`FEATURES` (without :data:`TORQUE_FEATURES`) in the
    0.5 s balance of :func:`mechanism_balance` (``g int tau + c int f`` beside them): at each
    step the feature that lowers the training logs' window residual most; per step the
    feature and per held-out log the RMS error over holding the rate."""
    chosen: list[str] = []
    pool = [f"feature:{n}" for n in FEATURES if n not in TORQUE_FEATURES]
    rows = []
    for _ in range(steps):
        best = _best_addition(
            pool, chosen, lambda names: [_windows_with(s, axis, names, horizon) for s in train],
            lambda y, fitted: float(np.sqrt(np.mean((y - fitted) ** 2) / np.mean(y ** 2))))
        chosen.append(best[0])
        held_ratio = {}
        for s in held:
            x, y = _windows_with(s, axis, tuple(chosen), horizon)
            held_ratio[s.name] = round(float(np.sqrt(np.mean((y - x @ best[2]) ** 2)
                                                     / np.mean(y ** 2))), 3)
        rows.append({"feature": best[0].split(":", 1)[1], "train_ratio": round(best[1], 3),
                     "coef": [float(f"{c:.3g}") for c in best[2]], "heldout_ratio": held_ratio})
    return rows


def flapping_timing(train: list[RotationSignals], held: list[RotationSignals], axis: int,
                    *, cutoff_hz: float = 2.0) -> dict:
    """The low-band balance ``M - tau = c f(t - d)`` per delay d of :data:`FLAPPING_DELAYS_S`
    (a wake or inflow that settles after the velocity changes), fitted on the training logs
    together: per delay (ms) c, the training residual RMS and each held-out log's (N m);
    ``best_per_log``: each log's own best delay (ms) and its residual RMS over the undelayed
    one's."""
    out = {}
    sos = signal.butter(2, cutoff_hz, fs=RATE_HZ, output="sos")
    low = lambda x: signal.sosfiltfilt(sos, x - x.mean())            # noqa: E731

    def part(s, d):
        x, y = low(delayed(s.flapping[:, axis], d)), low(s.moment[:, axis] - s.torque[:, axis])
        return x - x.mean(), y - y.mean()

    for d in FLAPPING_DELAYS_S:
        parts = [part(s, d) for s in train]
        x = np.concatenate([p[0] for p in parts])
        y = np.concatenate([p[1] for p in parts])
        c = float(x @ y) / float(x @ x)
        out[f"{1e3 * d:+.0f}"] = {
            "flapping": float(f"{c:.4g}"), "train_rms": float(f"{np.std(y - c * x):.3g}"),
            "heldout_rms": {s.name: float(f"{np.std(part(s, d)[1] - c * part(s, d)[0]):.3g}")
                            for s in held}}
    best = {}
    for s in [*train, *held]:
        rms = []
        for d in FLAPPING_DELAYS_S:
            x, y = part(s, d)
            rms.append(float(np.std(y - (x @ y) / (x @ x) * x)))
        k = int(np.argmin(rms))
        best[s.name] = {"delay_ms": round(1e3 * FLAPPING_DELAYS_S[k]),
                        "rms_ratio": round(rms[k] / rms[FLAPPING_DELAYS_S.index(0.0)], 3)}
    out["best_per_log"] = best
    return out


def analyse_mechanisms(train_s: list[RotationSignals], held_s: list[RotationSignals]) -> dict:
    """Every mechanism of :data:`MECHANISMS` (those the logs allow) and each feature of
    :data:`FEATURES` alone through :func:`mechanism_balance`, :func:`feature_selection`,
    :func:`windowed_selection` and :func:`flapping_timing`, per axis."""
    out = {}
    avail = [m.name for m in train_s[0].mechanisms]
    for axis, axis_name in enumerate(AXES):
        entry = {"mechanisms": {}, "features": {}}
        for name in MECHANISMS:
            if name in avail:
                entry["mechanisms"][name] = {
                    "labels": list(_mechanism(train_s[0], name).labels),
                    **mechanism_balance(train_s, held_s, axis, (name,))}
        for feat in FEATURES:
            res = mechanism_balance(train_s, held_s, axis, (f"feature:{feat}",))
            entry["features"][feat] = {
                "coef": res["pooled"]["coef"][1],
                "per_log_factor": {k: v["factor"] for k, v in res["per_log"].items()},
                "heldout_factor": {k: v["factor"] for k, v in res["pooled"]["heldout"].items()}}
        entry["selection"] = feature_selection(train_s, held_s, axis)
        entry["windowed_selection"] = windowed_selection(train_s, held_s, axis)
        entry["flapping_timing"] = flapping_timing(train_s, held_s, axis)
        out[axis_name] = entry
    return out


def analyse(model: Path, train: list[Path], heldout: list[Path], *,
            mechanisms: str = "no") -> dict:
    """Every table of the analysis as a JSON-ready dict (see the module docstring);
    ``mechanisms``: "no", "also" (adds ``mechanisms``: :func:`analyse_mechanisms`) or "only"
    (that section alone)."""
    params = load_params(model)
    sigs = {}
    for path in [*train, *heldout]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            sigs[path] = rotation_signals(load_log(path), params)
    train_s = [sigs[p] for p in train]
    held_s = [sigs[p] for p in heldout]
    if mechanisms == "only":
        return {"model": str(model), "mechanisms": analyse_mechanisms(train_s, held_s)}
    has_iv = all(s.instrument is not None for s in sigs.values())
    candidates = [c for c in CANDIDATES if c != "iv" or has_iv]
    out = {"model": str(model), "band_hz": list(BAND_HZ), "per_log": {}, "pooled": {}}
    for s in [*train_s, *held_s]:
        entry = {"heldout": s in held_s}
        if s.force_z is not None:
            (h, coh), = band_transfer([s.thrust], s.force_z, (BAND_HZ,))
            entry["z"] = {"gain": round(float(abs(h[0])), 3),
                          "phase_deg": round(float(np.degrees(np.angle(h[0]))), 1),
                          "coherence": round(coh, 3)}
        for axis, name in enumerate(AXES):
            entry[name] = {
                "bands": [{"band_hz": list(r.band_hz), "gain": round(r.gain, 3),
                           "phase_deg": round(r.phase_deg, 1),
                           "flap_gain": float(f"{r.flap_gain:.3g}"),
                           "coherence": round(r.coherence, 3)} for r in axis_response(s, axis)],
                "candidates": {c: _fit_json(fit_candidate([s], axis, c)) for c in candidates},
                "windowed_gain_0p5s": round(windowed_gain(s, axis)[0], 3),
                "low_band": low_band_balance(s, axis),
            }
        entry["low_band_common"] = low_band_common(s)
        out["per_log"][s.name] = entry
    for axis, name in enumerate(AXES):
        (g, c), ratios = windowed_heldout(train_s, held_s, axis)
        out.setdefault("windowed_0p5s", {})[name] = {
            "gain": round(g, 3), "flapping": float(f"{c:.3g}"),
            "heldout_rms_over_hold": {s.name: round(r, 3) for s, r in zip(held_s, ratios)}}
        pooled = {}
        for c in candidates:
            fit = fit_candidate(train_s, axis, c)
            pooled[c] = {**_fit_json(fit), "heldout_r2": {
                s.name: round(heldout_r2(fit, s, axis), 3) for s in held_s}}
        out["pooled"][name] = pooled
        out.setdefault("low_band_pooled", {})[name] = low_band_pooled(train_s, axis)
    if mechanisms == "also":
        out["mechanisms"] = analyse_mechanisms(train_s, held_s)
    return out


def _fit_json(fit: CandidateFit) -> dict:
    return {"gain": round(fit.gain, 3), "gain_ci": round(fit.gain_ci, 3),
            "parameter": float(f"{fit.parameter:.4g}"),
            "parameter_ci": float(f"{fit.parameter_ci:.3g}"),
            "flapping": float(f"{fit.flapping:.4g}"), "r2": round(fit.r2, 3)}


def print_mechanisms(result: dict) -> None:
    """The mechanisms' table to stdout: per axis and mechanism the pooled coefficients, the
    per-log factors (training and held out, each log's own fit) and the held-out factor and
    0.5 s ratio of the pooled fit."""
    for axis, entry in result.get("mechanisms", {}).items():
        for name, m in entry["mechanisms"].items():
            print(f"{axis} {name} ({', '.join(m['labels'])}): pooled coef "
                  + ", ".join(f"{c:.3g}+-{e:.2g}" for c, e in
                              zip(m["pooled"]["coef"], m["pooled"]["coef_ci"])))
            print("   per log coef / factor: " + "; ".join(
                f"{k}: {'/'.join(f'{c:.3g}' for c in v['coef'][1:])} x{v['factor']:.2f}"
                for k, v in m["per_log"].items()))
            print("   held out: " + "; ".join(
                f"{k}: {v['flapping_only_rms']:.3g} -> {v['residual_rms']:.3g} N m "
                f"(x{v['factor']:.2f}, needed {v['needed_rms']:.3g}), 0.5 s "
                f"{m['windowed_0p5s'][k]['flapping_only']:.2f} -> "
                f"{m['windowed_0p5s'][k]['ratio']:.2f}"
                for k, v in m["pooled"]["heldout"].items()))
        feats = sorted(entry["features"].items(),
                       key=lambda kv: -np.median(list(kv[1]["heldout_factor"].values())))
        print(f"{axis} features by held-out factor: " + "; ".join(
            f"{k} " + "/".join(f"{x:.2f}" for x in v["heldout_factor"].values())
            for k, v in feats[:8]))
        for step in entry["windowed_selection"]:
            print(f"{axis} 0.5 s selection + {step['feature']}: train {step['train_ratio']:.2f}"
                  ", held out " + "/".join(f"{x:.2f}" for x in step["heldout_ratio"].values()))
        print(f"{axis} flapping delay, best per log (ms, residual ratio): " + "; ".join(
            f"{k} {v['delay_ms']:+d} {v['rms_ratio']:.2f}"
            for k, v in entry["flapping_timing"]["best_per_log"].items()))
        for step in entry["selection"]:
            print(f"{axis} selection + {step['feature']}: train RMS {step['train_rms']:.3g}, "
                  "held-out factor " + "/".join(f"{x:.2f}" for x in
                                                 step["heldout_factor"].values())
                  + ", 0.5 s " + "/".join(f"{v['ratio']:.2f}" for v in
                                           step["windowed_0p5s"].values()))


def print_summary(result: dict) -> None:
    """The per-log tables to stdout."""
    if "per_log" not in result:
        print_mechanisms(result)
        return
    for axis, w in result.get("windowed_0p5s", {}).items():
        print(f"0.5 s balance {axis}: g {w['gain']:.3f}, flapping {w['flapping']:.3g}; held-out "
              "RMS / hold " + ", ".join(f"{k} {v:.2f}" for k, v in
                                        w["heldout_rms_over_hold"].items()))
    units = {"scale": "delay ms", "iv": "delay ms", "lag": "tau ms", "damping": "k N m s/rad"}
    for name, entry in result["per_log"].items():
        z = entry.get("z")
        print(f"{name}{' (held out)' if entry['heldout'] else ''}"
              + (f": z {z['gain']:.2f}/{z['phase_deg']:+.0f} deg/coh {z['coherence']:.2f}"
                 if z else ""))
        for axis in AXES:
            e = entry[axis]
            bands = " ".join(f"{b['band_hz'][0]:g}-{b['band_hz'][1]:g}:{b['gain']:.2f}/"
                             f"{b['phase_deg']:+.0f}/{b['coherence']:.2f}" for b in e["bands"])
            fits = "; ".join(
                f"{c} g {f['gain']:.2f}+-{f['gain_ci']:.2f} "
                f"{units[c]} {f['parameter'] * (1 if c == 'damping' else 1e3):.3g}"
                f" R2 {f['r2']:.2f}" for c, f in e["candidates"].items())
            lb = e["low_band"]
            print(f"  {axis}: {bands}\n    {fits}; 0.5 s gain {e['windowed_gain_0p5s']:.2f}"
                  f"\n    below 2 Hz: torque RMS {lb['torque_rms']:.3g}, moment RMS "
                  f"{lb['moment_rms']:.3g} N m; flapping {lb['flapping']:.3g} explains R^2 "
                  f"{lb['balance_r2']:.2f} of the difference, leaving {lb['residual_rms']:.3g} N m")
    for axis, lb in result.get("low_band_pooled", {}).items():
        print(f"below 2 Hz, {lb['logs']} training logs together: {axis} flapping "
              f"{lb['flapping']:.4g} +- {lb['ci']:.3g} kg m/rad (95 %, jackknife over logs)")
    for axis, pooled in result["pooled"].items():
        print(f"pooled {axis}: " + "; ".join(
            f"{c} g {f['gain']:.3f}+-{f['gain_ci']:.3f} {units[c]} "
            f"{f['parameter'] * (1 if c == 'damping' else 1e3):.3g}+-"
            f"{f['parameter_ci'] * (1 if c == 'damping' else 1e3):.2g} R2 {f['r2']:.2f} "
            f"held-out R2 " + "/".join(f"{v:.2f}" for v in f["heldout_r2"].values())
            for c, f in pooled.items()))
    print_mechanisms(result)


def flapping_effect_file(effects_file: Path, pooled: dict, train: list[Path]) -> str:
    """The text of effect file ``effects_file`` plus ``blade_flapping`` with ``roll`` and
    ``pitch`` = ``pooled[axis]["flapping"]`` (:func:`low_band_pooled` on ``train``), each with
    its unit and source; refused when the file already holds ``blade_flapping`` or when no
    axis is identified (``pooled[axis]["identified"]``, the package estimator's acceptance;
    an axis not identified is left out)."""
    from quadsim.effects.effectfile import load_effect_file, render_effect_file

    model = load_effect_file(effects_file)
    names = [e.name for e in model.effects.effects]
    if "blade_flapping" in names:
        raise InputError(f"{effects_file}: blade_flapping is already in it")
    entries = [(e.name, {k: (v, model.sources[(e.name, k)]) for k, v in e.values().items()
                         if (e.name, k) in model.sources}) for e in model.effects.effects]
    logs = ", ".join(Path(p).name for p in train)
    kept = [axis for axis in AXES if pooled[axis].get("identified", True)]
    if not kept:
        raise InputError("--write-effects: blade flapping not identified on the --train logs: "
                         + "; ".join(pooled[axis]["why"] for axis in AXES))
    entries.append(("blade_flapping", {
        axis: (pooled[axis]["flapping"],
               f"python -m benchmarks.rotation_analysis on {len(train)} training log(s) {logs}, "
               f"on top of {Path(effects_file).name}: below 2 Hz, rotor torque minus the "
               f"body's moment on the flapping regressor, the logs together (low_band_pooled: "
               f"quadsim.identify.flapping), {pooled[axis]['flapping']:.4g} +- "
               f"{pooled[axis]['ci']:.2g} (95 %, jackknife over logs)") for axis in kept}))
    header = ("Written by python -m benchmarks.rotation_analysis --write-effects (rerun it "
              "instead of editing by hand): " + ", ".join([*names, "blade_flapping"])
              + f" on {model.params}.")
    return render_effect_file(model.params, model.description, entries, header)


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", type=Path, required=True, help="parameter set (TOML)")
    parser.add_argument("--train", type=Path, nargs="+", required=True)
    parser.add_argument("--heldout", type=Path, nargs="*", default=[])
    parser.add_argument("--json", type=Path, metavar="OUT.json")
    parser.add_argument("--effects-file", type=Path, metavar="IN.toml",
                        help="effect file the fitted flapping is added to")
    parser.add_argument("--write-effects", type=Path, metavar="OUT.toml",
                        help="write --effects-file plus blade_flapping (roll, pitch) fitted "
                             "below 2 Hz on the --train logs")
    parser.add_argument("--mechanisms", choices=("no", "also", "only"), default="no",
                        help="the low-band mechanisms the flapping leaves (analyse_mechanisms): "
                             "beside the rest or alone")
    args = parser.parse_args(argv)
    if (args.write_effects is None) != (args.effects_file is None):
        raise InputError("--write-effects and --effects-file go together")
    if args.write_effects is not None and args.mechanisms == "only":
        raise InputError("--write-effects needs the low-band fit: not with --mechanisms only")
    result = analyse(args.model, args.train, args.heldout, mechanisms=args.mechanisms)
    print_summary(result)
    if args.write_effects is not None:
        atomic_write_text(args.write_effects, flapping_effect_file(
            args.effects_file, result["low_band_pooled"], args.train))
        print(f"wrote {args.write_effects}")
    if args.json:
        atomic_write_text(args.json, json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
