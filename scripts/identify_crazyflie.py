"""Write models/crazyflie21.toml: the Crazyflie 2.1 Brushless parameter set.

Facts (mass, rotor layout, spin, torque/thrust ratio, rotor radius, inertia range) come from
the data README of the crazyflie21_brushless flights; the thrust factor b and the
command -> speed map are identified here from the *nominal* flights only (never from
``mixed/``):

* b: least squares through the origin of the body-z force balance
  ``m * f_z = b * sum_i Omega_i^2`` over every sample of every nominal flight, with the
  accelerometer specific force and rotor speeds smoothed by the same Savitzky–Golay filter
  (quadsim.gap.residual). Its spread is the standard deviation of the per-flight estimates.
* motor map (the set's ``[motor_map]``): ``identify --logs``' own motor fit
  (:func:`quadsim.identify.motor_fits.fit_motor_map`: per rotor ``Omega = L_tau[a + k cmd
  (1 + gamma (v - v_ref))]``, L_tau a first-order lag, tau on a 2.5 ms grid, gamma the
  battery-voltage gain about the flights' median voltage v_ref) on the flights as ``identify
  --logs`` loads them, pooled: the steady line a + k cmd stored at cmd = 0 and 1 (trusted
  inside the flown range, about 0.35-0.49), ``reference_voltage`` v_ref, ``voltage_gain``
  gamma (the rotors' mean; :class:`quadsim.vehicle.params.MotorMap` scales the whole steady
  speed by 1 + gamma (v - v_ref), the fit only k cmd: the two differ by a gamma (v - v_ref),
  at most 6 rad/s, 0.4 % of the hover speed, over the flights' 3.6-3.9 V) and
  ``time_constant`` tau, with its 95 % interval and the per-flight fits' spread
  (:func:`motor_lag`). Why the voltage law: the battery falls as the flights go on and the
  controller raises the commands to hold the thrust, so a line without it reads the slope
  about 30 % low, and a command-only log's speeds from it are off by the battery's state
  (docs/logs.md "Diagnosis from commands alone"; CHANGELOG.md, "the motor map with its
  battery-voltage law").
* d = 0.006 m * b (README: torque/thrust ratio of Crazyflie 2.x propellers), checked against
  the flights' yaw balance (below).
* motor time constant tau (s): ``identify --logs``' own motor fit
  (:func:`quadsim.identify.motor_fits.fit_motor_map`: per rotor ``Omega = L_tau[a + k cmd
  (1 + gamma (v - v_ref))]``, L_tau a first-order lag, tau on a 2.5 ms grid) on the flights
  as ``identify --logs`` loads them, pooled, with its 95 % interval and the per-flight fits'
  spread (:func:`motor_lag`).

Not ``python -m quadsim.identify --logs``: that command identifies d (yaw balance,
instrumental variables), Ixx, Iyy and a lagged, voltage-dependent motor map from the logs.
On these flights it gives the same b (3.703e-8 N s^2/rad^2) but d = 0.00148 m x b, a hover
figure of merit of 1.7, which the vehicle guards refuse (nothing written); this set keeps
the README's facts instead (``python -m quadsim.identify --logs
../shared/data/crazyflie21_brushless/nominal/flight_*.csv.gz --vehicle SKELETON.toml -o
cf.toml``, the skeleton being this file without thrust_factor, drag_factor, max_speed and
[motor_map]).

``--yaw-balance`` writes nothing and prints what the flights say about d (why it stays the
README's: docs/identification.md, "What the crazyflie21 flights say about d"). It fits the yaw
balance ``Izz wdot_z + (Iyy - Ixx) w_x w_y = d X + sum_k c_k x_k`` (X = -sum_i s_i
Omega_i^2; x_k the z torque per unit parameter of the library's ``rotor_drag``,
``gyroscopic`` spin-up and ``rate_damping.z`` on the logged states) given the set's Izz, by
instrumental variables and least squares, over the whole band and in bands (:func:`yaw_balance`),
and roll, pitch and yaw as quadsim.identify.rotation fits Ixx, Iyy (:func:`delayed_band_fits`).

``--air-loads`` writes nothing and prints, per nominal flight and per group of five flights
flown at one speed, what the flights say about the air loads the set lacks: blade flapping
(roll, pitch) from the roll/pitch moment balance and rotor drag from the body x/y force
balance below 2 Hz, each regressor the library effect's own load per unit parameter, with the
flight's RMS speed, hover thrust as a mass and battery voltage (:func:`air_loads`;
docs/identification.md, "The crazyflie21 set's air loads"). ``--side-force`` prints each
flight's steady body-frame side force after the set and those air loads, and the lean of
rotor 2 it would read as beyond the nominal flights' (:func:`side_forces`; benchmarks/HISTORY.md,
"Is the mixed campaign's rotor-2 tilt shared?").

Usage::

    python scripts/identify_crazyflie.py --air-loads        # per flight; writes nothing
    python scripts/identify_crazyflie.py --side-force [--logs LOG...]   # writes nothing
    python scripts/identify_crazyflie.py [--data ../shared/data/crazyflie21_brushless]
                                         [--out models/crazyflie21.toml]
    python scripts/identify_crazyflie.py --yaw-balance      # the table above; writes nothing
    python scripts/identify_crazyflie.py --yaw-balance --logs LOG... --out SET.toml
                                         # the same for another vehicle's logs and set
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from quadsim.core.errors import InputError, QuadsimWarning, run_cli  # noqa: E402
from quadsim.core.executor import limit_numeric_threads  # noqa: E402
from quadsim.core.files import atomic_write_text  # noqa: E402
from quadsim.gap.residual import flight_states  # noqa: E402
from quadsim.logs.flightlog import load_log  # noqa: E402

MASS = 0.037            # kg, README: total mass with battery
HUB = 0.0354            # m, README: x and y hub offsets (0.050 m from the centre)
TORQUE_RATIO = 0.006    # m, README: torque/thrust ratio (firmware value, brushed CF 2.x)
RADIUS = 0.0275         # m, README: rotor radius 0.025-0.03 m, midpoint
INERTIA = (2.05e-5, 2.05e-5, 3.05e-5)  # kg m^2, README literature range midpoints
README = "crazyflie21_brushless data README"


def identify(nominal: list[Path]) -> dict:
    """b (N s^2/rad^2), its per-flight spread, the flights' count and peak rotor speed
    (rad/s)."""
    numerator = denominator = 0.0
    per_flight, peak = [], 0.0
    for path in nominal:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            states = flight_states(load_log(path))
        omega2 = np.square(states.rotor_speed).sum(1)
        force_z = MASS * states.specific_force[:, 2]
        numerator += float(force_z @ omega2)
        denominator += float(omega2 @ omega2)
        per_flight.append(float(force_z @ omega2) / float(omega2 @ omega2))
        peak = max(peak, float(states.rotor_speed.max()))
    return {"b": numerator / denominator, "b_std": float(np.std(per_flight, ddof=1)),
            "flights": len(per_flight), "peak": peak}


@dataclass(frozen=True)
class MotorLag:
    """The rotors' command -> speed map through a first-order lag, as ``identify --logs``
    fits it: ``tau`` (s) pooled over the flights with its 95 % interval ``ci95`` (s; the
    fit's profile on its grid), the per-flight fits' ``per_flight`` (s, one per flight, in
    the order given); the pooled steady map ``speed`` (R, 2) rad/s at cmd 0 and 1 at the
    ``reference_voltage`` (V, the flights' median), its ``voltage_gain`` (1/V, the rotors'
    mean) and that gain's spread over the rotors ``gain_spread`` (1/V), the flown
    ``command_range`` and each rotor's ``r2``."""

    tau: float
    ci95: tuple[float, float]
    per_flight: tuple[float, ...]
    speed: tuple = ()
    reference_voltage: float | None = None
    voltage_gain: float = 0.0
    gain_spread: float = 0.0
    command_range: tuple[float, float] = (0.0, 1.0)
    r2: tuple = ()


def motor_lag(nominal: list[Path]) -> MotorLag:
    """:class:`MotorLag` of the flights: :func:`quadsim.identify.motor_fits.fit_motor_map` on
    all of them pooled, then on each alone (the flights loaded and cut as ``identify --logs``
    does, :func:`quadsim.identify.__main__._load_states`)."""
    from quadsim.identify.__main__ import _load_states, _series
    from quadsim.identify.motor_fits import fit_motor_map

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        states, _ = _load_states(list(nominal))
    series = [_series(s) for s in states]
    pooled = fit_motor_map(series)
    per_flight = tuple(float(fit_motor_map([s])["time_constant"]) for s in series)
    low, high = pooled["time_constant_ci"]
    return MotorLag(float(pooled["time_constant"]), (float(low), float(high)), per_flight,
                    tuple(tuple(row) for row in pooled["speed"]), pooled["reference_voltage"],
                    float(pooled["voltage_gain"]), float(pooled["voltage_gain_spread"]),
                    tuple(pooled["command_range"]), tuple(pooled["r2"]))


# ----------------------------------------------------------------------------- yaw balance

#: the yaw-balance terms besides d: (effect, its parameter at 1 unit, source). Each term's
#: regressor is the z torque the library's effect gives per unit of its parameter on the
#: logged states (quadsim.gap.residual.model_wrench), so it is the engines' own term.
YAW_TERMS = {
    "rotor_drag": ("rotor_drag", "coefficient", "kg/rad",
                   "in-plane rotor drag at the hubs: tau_z = -c sum_i Omega_i |r_i|^2 w_z "
                   "- c (S x v)_z (quadsim.effects.rotor_drag)"),
    "spin_up": ("gyroscopic", "rotor_inertia", "kg m^2",
                "spin-up reaction tau_z = -Jr sum_i s_i dOmega_i/dt "
                "(quadsim.effects.gyroscopic)"),
    "rate_damping": ("rate_damping", "z", "N m s/rad",
                     "tau_z = -k_z w_z (quadsim.effects.rate_damping)"),
}
#: the models compared (d alone, each term, rotor drag with spin-up) and the bands (Hz):
#: whole (each flight's mean removed), the yaw loop's trim band, then upward.
YAW_MODELS = ((), ("rotor_drag",), ("spin_up",), ("rate_damping",), ("rotor_drag", "spin_up"))
YAW_BANDS = ((0.0, float("inf")), (0.0, 0.5), (0.5, 2.0), (1.0, 16.0), (2.0, 4.0),
             (4.0, 8.0), (8.0, 16.0))
AIR_DENSITY = 1.225     # kg/m^3, ISA sea level (the vehicle guard's figure of merit)
#: the instruments' motor lag (s): ``identify --logs`` fits a 50 ms map lag on these flights;
#: without it the spin-up term's instrument (the commanded speeds' derivative) leads the
#: measured one by the motor's lag and the fit fails (R^2 < 0)
MAP_LAG_S = 0.05


@dataclass(frozen=True)
class YawFit:
    """One fit of the yaw balance: d (N m s^2/rad^2) and its 95 % interval given Izz
    (kg m^2), the other terms' values (their units in YAW_TERMS), R^2, the band (Hz)."""

    terms: tuple[str, ...]
    band: tuple[float, float]
    method: str
    d: float
    d_ci95: tuple[float, float]
    others: tuple[float, ...]
    r2: float


def _band(x: np.ndarray, dt: float, band: tuple[float, float]) -> np.ndarray:
    """``x`` (N, ...) less its mean, with its Fourier components outside ``band`` (Hz)
    removed."""
    spectrum = np.fft.rfft(x - x.mean(axis=0), axis=0)
    freq = np.fft.rfftfreq(len(x), dt)
    spectrum[(freq < band[0]) | (freq > band[1])] = 0.0
    return np.fft.irfft(spectrum, len(x), axis=0)


def yaw_regressors(states, params, terms: tuple[str, ...]):
    """(y, X, Z) of one flight: y the measured yaw torque (N m, Newton-Euler with the set's
    inertia), X (N, 1 + k) d's regressor -sum s_i Omega_i^2 and each term's yaw torque per
    unit parameter from the measured rotor speeds, Z the same from the commanded speeds
    (the set's motor map at the logged battery voltage, through a first-order lag MAP_LAG_S;
    their time derivative for the spin-up term): the instruments."""
    from scipy.signal import lfilter

    from quadsim.effects import parse_effect_spec
    from quadsim.gap.residual import measured_wrench, model_wrench, speed_of_command

    dt = float(states.t[1] - states.t[0])
    mm = params.motor_map       # at the logged battery voltage where the map has its law
    steady = speed_of_command(params, states.command) if mm is None or states.vbat is None \
        else mm.speed_at(states.command, states.vbat)
    pole = float(np.exp(-dt / MAP_LAG_S))           # first-order lag, started at rest
    commanded = lfilter([1.0 - pole], [1.0, -pole], steady - steady[0], axis=0) + steady[0]
    instrument = dataclasses.replace(states, rotor_speed=commanded,
                                     rotor_accel=np.gradient(commanded, dt, axis=0))
    spins = params.rotor_spins
    columns = []
    for source in (states, instrument):
        base = model_wrench(source, params, [])[1][:, 2]
        cols = [-(np.square(source.rotor_speed) @ spins)]
        for name in terms:
            effect, parameter, _, _ = YAW_TERMS[name]
            # at a small unit inside the effect's range (the torque is linear in it)
            unit = 1e-9
            spec = parse_effect_spec(f"{effect}:{parameter}={unit}")
            cols.append((model_wrench(source, params, [spec])[1][:, 2] - base) / unit)
        columns.append(np.stack(cols, axis=1))
    return measured_wrench(states, params)[1][:, 2], columns[0], columns[1]


#: seconds per block of the score's batch means (longer than the residual's correlation in
#: every band of YAW_BANDS: 0.5 Hz and above decorrelate within 2 s)
BLOCK_S = 2.0


def _fit(rows, terms, band, method: str) -> YawFit:
    """Pooled fit of y on X: least squares, or instrumental variables with Z
    (``beta = (Z'X)^-1 Z'y``). Covariance ``(Z'X)^-1 S (Z'X)^-T`` with S the sum over
    blocks of BLOCK_S seconds of each block's score ``sum z u`` times its transpose (batch
    means: band-passed residuals are correlated over about 1/bandwidth, which a correlation
    time from their autocorrelation, whose integral a band-pass sets to 0, would not see)."""
    parts = [tuple(_band(a, dt, band) for a in (y, x, z)) + (dt,) for y, x, z, dt in rows]
    y, x, z = (np.concatenate([p[k] for p in parts]) for k in range(3))
    if method == "LS":
        z = x
        parts = [(py, px, px, dt) for py, px, _, dt in parts]
    gram = np.linalg.inv(z.T @ x)
    beta = gram @ (z.T @ y)
    u = y - x @ beta
    scores = []
    for py, px, pz, dt in parts:
        g = pz * (py - px @ beta)[:, None]
        size = max(1, int(round(BLOCK_S / dt)))
        scores += [g[k:k + size].sum(axis=0) for k in range(0, len(g), size)]
    scores = np.array(scores)
    cov = gram @ (scores.T @ scores) @ gram.T
    se = np.sqrt(np.diag(cov))
    return YawFit(tuple(terms), band, method, float(beta[0]),
                  (float(beta[0] - 1.96 * se[0]), float(beta[0] + 1.96 * se[0])),
                  tuple(float(v) for v in beta[1:]), 1.0 - float(u @ u) / float(y @ y))


def yaw_balance(nominal: list[Path], params_path: Path, *,
                models: tuple[tuple[str, ...], ...] = YAW_MODELS) -> list[YawFit]:
    """Every model of ``models`` in every band of YAW_BANDS, instrumental variables and least
    squares, on the flights as ``identify --logs`` cuts them, given the set's Izz."""
    from quadsim.identify.__main__ import _load_states
    from quadsim.vehicle.params import load_params

    params = load_params(params_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        states, _ = _load_states(list(nominal))
    out = []
    for terms in models:
        rows = [(*yaw_regressors(s, params, terms), float(s.t[1] - s.t[0])) for s in states]
        for band in YAW_BANDS:
            for method in ("IV", "LS"):
                out.append(_fit(rows, terms, band, method))
    return out


#: the air loads' band (Hz): the figure-8s' air speed lives below it (one lap per 7-9 s
#: flight, 92 % of the held-out gap below 1 Hz), and there the rigid body's own torque
#: I omega_dot is small, so the rotors' moments trim what the air does (an inertia column
#: takes what is left of it)
AIR_BAND = (0.0, 2.0)


@dataclass(frozen=True)
class AirLoads:
    """What one flight (or a pooled group) says about the air loads the set lacks, each
    with its 95 % interval (batch means over BLOCK_S blocks), in the library's own
    parameters: ``blade_flapping.roll``/``.pitch`` (kg m/rad) from the roll/pitch moment
    balance, ``rotor_drag.coefficient`` (kg/rad) from the body x/y force balance; with the
    flight's RMS air speed (m/s, still air), its hover thrust as a mass (g: b sum Omega^2 /
    f_z, median) and its battery voltage (V, first and last second)."""

    name: str
    roll: tuple[float, float]
    pitch: tuple[float, float]
    drag_x: tuple[float, float]
    drag_y: tuple[float, float]
    rms_speed: float
    hover_mass_g: float
    vbat: tuple[float, float]


def _air_rows(states, params):
    """Per axis (roll, pitch, drag x, drag y) the (y, X) of one flight: y the residual of
    the set's model (N m or N: Newton-Euler with the set's mass and inertia less the set's
    rotor wrench), X the library effect's load per unit parameter on the logged states (the
    moments with the angular acceleration beside it: the inertia's share at low frequency)."""
    from quadsim.effects import parse_effect_spec
    from quadsim.gap.residual import measured_wrench, model_wrench

    force, torque = measured_wrench(states, params)
    base_f, base_t, _ = model_wrench(states, params, [])
    unit = 1e-9                       # inside every range; the loads are linear in it

    def per_unit(spec):
        f, t, _ = model_wrench(states, params, [parse_effect_spec(spec)])
        return (f - base_f) / unit, (t - base_t) / unit

    _, flap_roll = per_unit(f"blade_flapping:roll={unit}")
    _, flap_pitch = per_unit(f"blade_flapping:pitch={unit}")
    drag, _ = per_unit(f"rotor_drag:coefficient={unit}")
    accel = states.body_accel
    return [(torque[:, 0] - base_t[:, 0], np.stack([flap_roll[:, 0], accel[:, 0]], 1)),
            (torque[:, 1] - base_t[:, 1], np.stack([flap_pitch[:, 1], accel[:, 1]], 1)),
            (force[:, 0] - base_f[:, 0], drag[:, :1]),
            (force[:, 1] - base_f[:, 1], drag[:, 1:2])]


def air_loads(groups: list[tuple[str, list[Path]]], params_path: Path) -> list[AirLoads]:
    """:class:`AirLoads` of each named group of flights (one flight or several, pooled with
    each flight's mean removed), least squares in :data:`AIR_BAND`."""
    from quadsim.vehicle.params import load_params

    params = load_params(params_path)
    cache: dict[Path, tuple] = {}
    for path in {p for _, paths in groups for p in paths}:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            log = load_log(path)
            states = flight_states(log)
        dt = float(states.t[1] - states.t[0])
        omega2 = np.square(states.rotor_speed).sum(1)
        mass = params.thrust_factor * omega2 / states.specific_force[:, 2]
        speed = float(np.sqrt(np.mean(np.sum(np.square(states.velocity[:, :2]), 1))))
        second = max(1, int(round(1.0 / dt)))
        vbat = log.vbat
        volts = ((float(np.mean(vbat[:second])), float(np.mean(vbat[-second:])))
                 if vbat is not None else (float("nan"), float("nan")))
        cache[path] = (_air_rows(states, params), dt, speed, 1e3 * float(np.median(mass)),
                       volts)
    out = []
    for name, paths in groups:
        fits = []
        for axis in range(4):
            rows = [(cache[p][0][axis][0], cache[p][0][axis][1], cache[p][0][axis][1],
                     cache[p][1]) for p in paths]
            fit = _fit(rows, ("x",) * (rows[0][1].shape[1] - 1), AIR_BAND, "LS")
            fits.append((fit.d, 0.5 * (fit.d_ci95[1] - fit.d_ci95[0])))
        first = cache[paths[0]]
        out.append(AirLoads(name, *fits, rms_speed=float(np.mean([cache[p][2] for p in paths])),
                            hover_mass_g=float(np.mean([cache[p][3] for p in paths])),
                            vbat=(first[4][0], cache[paths[-1]][4][1])))
    return out


def print_air_loads(fits: list[AirLoads], params_path: Path) -> None:
    """The :func:`air_loads` table."""
    print(f"air loads against {params_path.name}, least squares {AIR_BAND[0]:g}-{AIR_BAND[1]:g}"
          f" Hz, 95 % intervals (batch means over {BLOCK_S:g} s)")
    print(f"{'flights':<10} {'RMS v m/s':>9} {'hover g':>8} {'vbat V':>11}  "
          f"{'flapping roll':>19} {'flapping pitch':>19} {'rotor drag x':>19} "
          f"{'rotor drag y':>19}")
    for f in fits:
        cells = " ".join(f"{v:>10.3e} ± {c:.1e}" for v, c in (f.roll, f.pitch, f.drag_x,
                                                              f.drag_y))
        print(f"{f.name:<10} {f.rms_speed:>9.2f} {f.hover_mass_g:>8.2f} "
              f"{f.vbat[0]:.2f}-{f.vbat[1]:.2f}  {cells}")


#: seconds per block of the steady side force's batch means
SIDE_BLOCK_S = 1.0


@dataclass(frozen=True)
class SideForce:
    """One flight's steady body-frame side force (N) after the set and its air loads
    (``models/effects/crazyflie21_nominal.toml``), with 95 % intervals (batch means over
    SIDE_BLOCK_S blocks), and its mean thrust of ``rotor`` (N): a rotor whose axis leans by a
    small angle a pushes T a sideways, so a force F beyond the references' reads as a lean of
    F / T (rad)."""

    name: str
    force: tuple[float, float]
    ci95: tuple[float, float]
    thrust: float


def side_forces(paths: list[Path], params_path: Path, effects_path: Path, *,
                rotor: int = 2) -> list[SideForce]:
    """:class:`SideForce` of each flight in ``paths`` (``rotor``: 1-based, the set's
    numbering)."""
    from quadsim.effects.effectfile import load_effect_file
    from quadsim.gap.residual import measured_wrench, model_wrench
    from quadsim.vehicle.params import load_params

    params = load_params(params_path)
    effects = load_effect_file(effects_path).effects.effects
    out = []
    for path in paths:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            states = flight_states(load_log(path))
        dt = float(states.t[1] - states.t[0])
        force = measured_wrench(states, params)[0] - model_wrench(states, params, effects)[0]
        size = max(2, int(round(SIDE_BLOCK_S / dt)))
        blocks = len(force) // size
        means = force[:blocks * size, :2].reshape(blocks, size, 2).mean(axis=1)
        ci = 1.96 * means.std(axis=0, ddof=1) / np.sqrt(blocks)
        thrust = params.thrust_factor * float(np.mean(np.square(states.rotor_speed[:, rotor - 1])))
        out.append(SideForce(path.name.split(".")[0], tuple(float(v) for v in means.mean(0)),
                             tuple(float(v) for v in ci), thrust))
    return out


def print_side_forces(flights: list[SideForce], references: list[SideForce]) -> None:
    """Each flight's steady side force and, beyond the references' mean, the lean of rotor 2
    it would read as."""
    ref = np.array([f.force for f in references])
    centre, spread = ref.mean(axis=0), ref.std(axis=0, ddof=1)
    print(f"{len(references)} nominal flights: side force x {1e3 * centre[0]:+.2f} (SD "
          f"{1e3 * spread[0]:.2f}), y {1e3 * centre[1]:+.2f} (SD {1e3 * spread[1]:.2f}) mN")
    print(f"{'flight':<11} {'Fx mN':>13} {'Fy mN':>13}   beyond the nominal mean, as rotor 2's "
          "lean toward x, y (deg)")
    for f in flights:
        extra = np.degrees((np.array(f.force) - centre) / f.thrust)
        ci = np.degrees(np.array(f.ci95) / f.thrust)
        print(f"{f.name:<11} {1e3 * f.force[0]:+6.2f} ± {1e3 * f.ci95[0]:.2f} "
              f"{1e3 * f.force[1]:+6.2f} ± {1e3 * f.ci95[1]:.2f}   "
              f"{extra[0]:+.2f} ± {ci[0]:.2f}, {extra[1]:+.2f} ± {ci[1]:.2f}")


#: the yaw loop's trim band (Hz): below it the yaw pattern moves without a yaw acceleration
TRIM_BAND = (0.0, 0.5)


def slow_yaw_pattern(nominal: list[Path], params_path: Path) -> tuple[float, float]:
    """(share of the yaw pattern X's variance in TRIM_BAND, R^2 of that slow part on the body
    velocity v_x, v_y), pooled over the flights (each flight's mean removed)."""
    from quadsim.core.frames import rotate_inverse
    from quadsim.identify.__main__ import _load_states
    from quadsim.vehicle.params import load_params

    spins = load_params(params_path).rotor_spins
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        states, _ = _load_states(list(nominal))
    slow, whole, velocity = [], [], []
    for st in states:
        dt = float(st.t[1] - st.t[0])
        x = -(np.square(st.rotor_speed) @ spins)
        whole.append(x - x.mean())
        slow.append(_band(x, dt, TRIM_BAND))
        velocity.append(_band(rotate_inverse(st.quat, st.velocity)[:, :2], dt, TRIM_BAND))
    slow, whole, velocity = (np.concatenate(a) for a in (slow, whole, velocity))
    coef = np.linalg.lstsq(velocity, slow, rcond=None)[0]
    u = slow - velocity @ coef
    return float(slow @ slow) / float(whole @ whole), 1.0 - float(u @ u) / float(slow @ slow)


#: bands (Hz) of the fits made as quadsim.identify.rotation makes Ixx, Iyy (its BAND_HZ first)
DELAYED_BANDS = ((4.0, 16.0), (4.0, 8.0), (8.0, 16.0), (1.0, 16.0), (0.5, 2.0))


@dataclass(frozen=True)
class AxisFit:
    """One axis fitted as quadsim.identify.rotation fits Ixx, Iyy: roll and pitch give the
    inertia (kg m^2, torque ``b l Omega^2`` on the angular acceleration), yaw gives d
    (N m s^2/rad^2, ``Izz wdot_z + (Iyy - Ixx) w_x w_y`` on ``-sum s_i Omega_i^2``, given the
    set's Izz); 95 % interval by delete-one-flight jackknife; R^2; the median per-flight delay
    (s) of the body behind the logged rotor speeds."""

    axis: str
    band: tuple[float, float]
    value: float
    ci95: tuple[float, float]
    r2: float
    delay: float


def delayed_band_fits(nominal: list[Path], params_path: Path) -> list[AxisFit]:
    """Roll, pitch and yaw in each band of DELAYED_BANDS: zero-phase Butterworth band-pass,
    each flight's rotor data shifted by its best delay of rotation.DELAY_GRID_S (best R^2 on
    that axis), least squares over all flights (quadsim.identify.rotation's method, the yaw
    added)."""
    from scipy import signal

    from quadsim.identify.__main__ import _load_states
    from quadsim.identify.rotation import DELAY_GRID_S, _shift
    from quadsim.vehicle.params import load_params

    params = load_params(params_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        states, _ = _load_states(list(nominal))
    inertia, b = params.inertia, params.thrust_factor
    arms = params.rotor_positions - params.com
    out = []
    for band in DELAYED_BANDS:
        for axis, name in enumerate(("roll", "pitch", "yaw")):
            chosen = []
            for st in states:
                dt = float(st.t[1] - st.t[0])
                sos = signal.butter(4, band, btype="bandpass", fs=1.0 / dt, output="sos")
                omega2, w = np.square(st.rotor_speed), st.body_rate
                if axis < 2:        # rotation.py's roles: torque = I x (angular acceleration)
                    torque = b * (omega2 @ arms[:, 1] if axis == 0 else -(omega2 @ arms[:, 0]))
                    body = st.body_accel[:, axis]
                else:               # yaw: measured torque = d x pattern
                    torque = -(omega2 @ params.rotor_spins)
                    body = (inertia[2, 2] * st.body_accel[:, 2]
                            + (inertia[1, 1] - inertia[0, 0]) * w[:, 0] * w[:, 1])
                body = signal.sosfiltfilt(sos, body)
                tries = []
                for delay in DELAY_GRID_S:
                    x = signal.sosfiltfilt(sos, _shift(torque, delay / dt))
                    y, reg = (x, body) if axis < 2 else (body, x)
                    slope = float(reg @ y) / float(reg @ reg)
                    u = y - slope * reg
                    tries.append((1.0 - float(u @ u) / float(y @ y), delay, y, reg))
                chosen.append(max(tries, key=lambda item: item[0]))

            def solve(rows):
                y = np.concatenate([r[2] for r in rows])
                reg = np.concatenate([r[3] for r in rows])
                slope = float(reg @ y) / float(reg @ reg)
                return slope, 1.0 - float(np.sum((y - slope * reg) ** 2)) / float(y @ y)

            value, r2 = solve(chosen)
            reps = np.array([solve(chosen[:k] + chosen[k + 1:])[0] for k in range(len(chosen))])
            g = len(reps)
            se = float(np.sqrt((g - 1) / g * np.sum((reps - reps.mean()) ** 2)))
            out.append(AxisFit(name, band, value, (value - 1.96 * se, value + 1.96 * se), r2,
                               float(np.median([c[1] for c in chosen]))))
    return out


def print_yaw_balance(fits: list[YawFit], params_path: Path) -> None:
    """The table: d, its interval, the other terms, R^2, and the figure of merit at the
    set's Izz and at the largest Izz a flat frame allows (Ixx + Iyy)."""
    from quadsim.vehicle.guards import figure_of_merit
    from quadsim.vehicle.params import load_params

    params = load_params(params_path)
    b, radius = params.thrust_factor, params.rotor_radius
    izz, izz_max = params.inertia[2, 2], params.inertia[0, 0] + params.inertia[1, 1]
    print(f"yaw balance on the logs, given Izz {izz:.3g} kg m^2 (b {b:.4g}); "
          f"FM* at Izz = Ixx + Iyy = {izz_max:.3g}")
    for f in fits:
        hi = "" if np.isinf(f.band[1]) else f"{f.band[1]:g}"
        band = "whole" if not hi else f"{f.band[0]:g}-{hi} Hz"
        others = ", ".join(f"{t} {v:.3g} {YAW_TERMS[t][2]}" for t, v in zip(f.terms, f.others))
        fm = figure_of_merit(b, f.d, AIR_DENSITY, radius) if f.d > 0 else float("inf")
        fm_max = fm * izz / izz_max
        print(f"{'d + ' + ' + '.join(f.terms) if f.terms else 'd':28s} {band:11s} {f.method} "
              f"d {f.d:.3e} [{f.d_ci95[0]:.3e}, {f.d_ci95[1]:.3e}] = {1e3 * f.d / b:.2f} mm x b"
              f"  FM {fm:.2f} FM* {fm_max:.2f}  R^2 {f.r2:.3f}  {others}")


def print_axis_fits(fits: list[AxisFit], params_path: Path) -> None:
    """The second table: per band, Ixx, Iyy and d (with d/b and the figure of merit)."""
    from quadsim.vehicle.guards import figure_of_merit
    from quadsim.vehicle.params import load_params

    params = load_params(params_path)
    b = params.thrust_factor
    print("as quadsim.identify.rotation (Butterworth band, per-flight delay, jackknife CI):")
    for f in fits:
        band = f"{f.band[0]:g}-{f.band[1]:g} Hz"
        if f.axis == "yaw":
            fm = (figure_of_merit(b, f.value, AIR_DENSITY, params.rotor_radius)
                  if f.value > 0 else float("inf"))
            what = (f"d {f.value:.3e} [{f.ci95[0]:.3e}, {f.ci95[1]:.3e}] = "
                    f"{1e3 * f.value / b:.2f} mm x b, FM {fm:.2f}")
        else:
            what = f"I {f.value:.3e} [{f.ci95[0]:.3e}, {f.ci95[1]:.3e}] kg m^2"
        print(f"{band:10s} {f.axis:5s} {what}  R^2 {f.r2:.2f}  median delay "
              f"{1e3 * f.delay:+.1f} ms")


def render(fit: dict, lag: MotorLag) -> str:
    """The parameter set's TOML text: ``fit`` from :func:`identify`, ``lag`` from
    :func:`motor_lag`."""
    from quadsim.identify.motor_fits import LAG_GRID_S

    b, d = fit["b"], TORQUE_RATIO * fit["b"]
    src_b = (f"identified by scripts/identify_crazyflie.py: body-z force balance m*f_z = "
             f"b*sum(Omega^2), accelerometer, {fit['flights']} nominal flights; per-flight "
             f"std {fit['b_std']:.2e}")
    lo, hi = lag.command_range
    src_map = (f"scripts/identify_crazyflie.py: identify --logs' motor fit "
               f"(quadsim.identify.motor_fits.fit_motor_map: per-rotor steady line through a "
               f"first-order lag and the battery-voltage law) on the {fit['flights']} nominal "
               f"flights pooled, R^2 {min(lag.r2):.3f}-{max(lag.r2):.3f} (flown cmd "
               f"{lo:.2f}-{hi:.2f}; outside that an extrapolation)")
    src_v = (f"scripts/identify_crazyflie.py: the median battery voltage of the "
             f"{fit['flights']} nominal flights, where the map's speed is stated")
    src_gain = (f"scripts/identify_crazyflie.py: the same motor fit's voltage gain, the "
                f"rotors' mean (spread over the rotors {lag.gain_spread:.2g} 1/V)")
    speeds = ", ".join(f"[{a:.1f}, {e:.1f}]" for a, e in lag.speed)
    spread = np.array(lag.per_flight)
    src_tau = (f"identify --logs' motor fit (quadsim.identify.motor_fits.fit_motor_map: per-rotor "
               f"map through a first-order lag, with the battery-voltage law; grid "
               f"{1e3 * (LAG_GRID_S[1] - LAG_GRID_S[0]):g} ms) on "
               f"the {fit['flights']} nominal flights pooled, 95 % {lag.ci95[0]:.4f}-"
               f"{lag.ci95[1]:.4f} s; per flight {spread.min():.4f}-{spread.max():.4f} s "
               f"(mean {spread.mean():.4f}, SD {spread.std(ddof=1):.4f}); written by "
               f"scripts/identify_crazyflie.py")
    rotors = [("1", HUB, -HUB, "ccw", "front-right"), ("2", -HUB, -HUB, "cw", "rear-right"),
              ("3", -HUB, HUB, "ccw", "rear-left"), ("4", HUB, HUB, "cw", "front-left")]
    rotor_text = "".join(
        f'\n[[rotor]]\nname = "{n}"\nposition = {{ value = [{x}, {y}, 0.0], unit = "m", '
        f'source = "{README}: motor {n} {where}, hub offsets +-0.0354 m (+-5 %)" }}\n'
        f'spin = "{s}"\n' for n, x, y, s, where in rotors)
    ixx, iyy, izz = INERTIA
    inertia = f"[[{ixx}, 0.0, 0.0], [0.0, {iyy}, 0.0], [0.0, 0.0, {izz}]]"
    src_inertia = (f"{README}: midpoints of the Crazyflie 2.x literature range "
                   "(not measured for this vehicle)")
    src_d = (f"{README}: torque/thrust ratio 0.006 m times the identified b; checked on the "
             "nominal flights (scripts/identify_crazyflie.py --yaw-balance): their yaw balance "
             "at 4-8 Hz, where roll and pitch follow the rigid body (R^2 0.95-0.96), reads "
             "0.0056 m x b, 95 % [0.0049, 0.0063], given Izz; no constant d fits every band "
             "(docs/identification.md)")
    max_speed = f"{max(2750.0, fit['peak']):.1f}"
    src_max = ("thrust_stand/pwm_rpm_log.csv: rpm4 peak 26304 rpm "
               "(rpm1-3 unreliable per its authors)")
    src_radius = f"{README}: rotor radius 0.025-0.03 m, midpoint"
    return f'''# Parameter set "crazyflie21": Crazyflie 2.1 Brushless as flown in nominal/ flights.
# Written by scripts/identify_crazyflie.py (do not edit by hand; rerun the script).
schema = "quadsim.vehicle.params/1"
name = "crazyflie21"
description = "Crazyflie 2.1 Brushless, 37 g quad-X; b identified from the nominal flights"

[body]
mass = {{ value = {MASS}, unit = "kg", source = "{README}: total mass with battery" }}
com = {{ value = [0.0, 0.0, 0.0], unit = "m", source = "assumed: symmetric frame" }}
inertia = {{ value = {inertia}, unit = "kg m^2", source = "{src_inertia}" }}

[rotors]
thrust_factor = {{ value = {b:.5g}, unit = "N s^2/rad^2", source = "{src_b}" }}
drag_factor = {{ value = {d:.5g}, unit = "N m s^2/rad^2", source = "{src_d}" }}
max_speed = {{ value = {max_speed}, unit = "rad/s", source = "{src_max}" }}
radius = {{ value = {RADIUS}, unit = "m", source = "{src_radius}" }}

[motor_map]
command_unit = "1"
command = {{ value = [0.0, 1.0], unit = "1", source = "{src_map}" }}
speed = {{ value = [{speeds}], unit = "rad/s", source = "{src_map}" }}
reference_voltage = {{ value = {lag.reference_voltage:.4f}, unit = "V", source = "{src_v}" }}
voltage_gain = {{ value = {lag.voltage_gain:.4g}, unit = "1/V", source = "{src_gain}" }}
time_constant = {{ value = {lag.tau:.4g}, unit = "s", source = "{src_tau}" }}
{rotor_text}'''


@run_cli
@limit_numeric_threads
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    root = Path(__file__).resolve().parent.parent
    parser.add_argument("--data", type=Path,
                        default=root.parent / "shared/data/crazyflie21_brushless",
                        help="folder holding nominal/flight_*.csv.gz")
    parser.add_argument("--out", type=Path, default=root / "models/crazyflie21.toml")
    parser.add_argument("--yaw-balance", action="store_true",
                        help="print the yaw balance's fits of d (models x bands) against the "
                             "set at --out; write nothing")
    parser.add_argument("--air-loads", action="store_true",
                        help="print what each nominal flight and each group of flights say "
                             "about blade flapping and rotor drag against the set at --out; "
                             "write nothing")
    parser.add_argument("--side-force", action="store_true",
                        help="print each log's (--logs; default nominal/) steady side force "
                             "after the set and its air loads, and the rotor-2 lean it would "
                             "read as beyond the nominal flights'; write nothing")
    parser.add_argument("--logs", type=Path, nargs="+",
                        help="with --yaw-balance: these logs instead of nominal/ (another "
                             "vehicle's, with --out naming its parameter set)")
    args = parser.parse_args(argv)
    if args.logs and not (args.yaw_balance or args.air_loads or args.side_force):
        raise InputError("--logs: only with --yaw-balance, --air-loads or --side-force (the "
                         "set is identified from nominal/ only)")
    nominal = args.logs or sorted((args.data / "nominal").glob("flight_*.csv*"))
    if not nominal:
        raise InputError(f"{args.data / 'nominal'}: no flight_*.csv(.gz) files")
    missing = [p for p in nominal if not p.is_file()]
    if missing:
        raise InputError(f"{missing[0]}: --logs: no such file")
    if args.side_force:
        own = sorted((args.data / "nominal").glob("flight_*.csv*"))
        effects = args.out.parent / "effects" / f"{args.out.stem}_nominal.toml"
        references = side_forces(own, args.out, effects)
        flights = references if not args.logs else side_forces(nominal, args.out, effects)
        print_side_forces(flights, references)
        return 0
    if args.air_loads:
        groups = [(p.name.split(".")[0], [p]) for p in nominal]
        if len(nominal) == 20:          # nominal/: five flights at each of four speeds
            groups += [(f"{k:02d}-{k + 4:02d}", nominal[k:k + 5]) for k in (0, 5, 10, 15)]
            groups += [("00-09", nominal[:10]), ("10-19", nominal[10:])]
        print_air_loads(air_loads(groups, args.out), args.out)
        return 0
    if args.yaw_balance:
        print_yaw_balance(yaw_balance(nominal, args.out), args.out)
        share, r2 = slow_yaw_pattern(nominal, args.out)
        print(f"yaw pattern X below {TRIM_BAND[1]:g} Hz: {100 * share:.0f} % of its variance; "
              f"R^2 of that slow part on the body velocity v_x, v_y: {r2:.2f}")
        print_axis_fits(delayed_band_fits(nominal, args.out), args.out)
        return 0
    fit, lag = identify(nominal), motor_lag(nominal)
    atomic_write_text(args.out, render(fit, lag))
    print(f"b = {fit['b']:.5g} N s^2/rad^2 (per-flight std {fit['b_std']:.2g}, "
          f"{fit['flights']} flights), motor time constant {1e3 * lag.tau:.1f} ms "
          f"(95 % {1e3 * lag.ci95[0]:.1f}-{1e3 * lag.ci95[1]:.1f}) -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
