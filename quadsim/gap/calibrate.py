"""Calibration: the nominal parameter set fitted on the reference flights (what every
reference shares goes into the model), its residual statistics as the noise model of every
later comparison, and the self-check of the references (each judged against the others).

The references' self-check
--------------------------

The references judged against each other: the self-check, and what a reading's size is
compared with (practical significance).

Every run judges each reference flight against the other references (leave one out): the
calibrated shared parameters are reused (one flight moves them by about 1/n of its own
difference), while the two things fitted from the flights' residuals -- the discrepancy term
(:meth:`quadsim.gap.reference.Discrepancy.without`) and the lack-of-fit baseline
(``lof_mean``, ``lof_sd``: :func:`quadsim.gap.reference.moderated_spread`) -- are refitted
without it (:func:`leave_one_out`). What comes out:

- **false alarms**: the references that do not come out ``no_significant_gap``, with their
  verdict and the channels that drive it (the lack-of-fit channels, else the channels the
  reading differs most on from "no difference");
- **the references' own readings**: every explanation's fitted values on each reference
  flight (:class:`Spread`: per parameter, their mean and between-flight standard deviation).

**Practical significance** (:func:`negligible`): a reading on a judged flight is a
difference only when, on at least one of its own determined parameters, its 95 % interval
lies beyond :data:`PRACTICAL_Z` *physical* between-flight standard deviations ``tau`` of the
same reading on the references:

    |v - mean_ref| - 1.96 sqrt(sd_post^2 + se_mean^2) > PRACTICAL_Z tau

Each reference's reading v_i carries its own estimation noise (its posterior SD s_i), so
their sample variance is tau^2 + mean(s_i^2) in expectation: ``tau`` is the method-of-moments
random-effects estimate sqrt(max(0, var(v_i) - mean(s_i^2))) (:meth:`Spread.of`; ``var``
with ddof 1), the same estimator as the shared parameters' scatter (:meth:`PerFlight.scatter`).
The flight's own noise is counted once, in its interval; ``se_mean`` = sqrt(var(v_i) / n) is
the references' mean's own standard error.

The floor: tau^2 >= min(1, sqrt(2 / (n - 1))) var(v_i), one standard error of the sample
variance itself (normal readings). An estimate var - mean(s_i^2) of 0 or less says only that
the physical spread lies below what n readings resolve, not that it is nil, so ``tau`` is
never taken below the spread the references cannot exclude at one standard error; capped at
their whole scatter (reached at n = 3: the rule before the noise was taken out), shrinking as
n^(-1/4) (10 references: 0.69 of their scatter). The floor scales with the observed scatter,
not with the posterior SDs: where those exceed the readings' scatter (on real references,
most readings: docs/gap.md), a floor from them would widen the band beyond the scatter the
references actually show. A
reading that does not is what the references themselves show flight to flight (a real
vehicle's rotor that reads -3 % on one reference and +2 % on the next): it counts as "no
difference" (:func:`quadsim.gap.judge.posterior`), as an undetermined reading does. The
nuisance parameters (a signal's delay, a cable's swing at the first sample and its
damping, a propeller's speed exponent) are never a difference on their own.

At the flight's place (:func:`placed`), as the lack-of-fit baseline is
(:func:`quadsim.gap.reference.local_reference`): inside the references' range of places
along their envelope axis their spread holds; a flight at e > 0 beyond the outermost
reference meets each reading's trend over the references (ordinary least squares of their
readings v_i on their places u_i: slope b, var(b) = r^2 / S_uu, r^2 the residual variance
with n - 2 degrees of freedom): the mean moves by b e, se_mean^2 grows by var(b) e^2 (the
centre's extrapolation) and tau^2 by (b^2 + var(b)) e^2 (the trend may bend out there, as
the shared values' scatter). Fewer than 3 readings of a parameter, or their places spread
less than :data:`quadsim.gap.reference.MIN_SPREAD`: no trend is measured, the mean holds.

A set of references that does not judge itself clean -- more than :data:`FALSE_ALARM_SHARE`
of them not ``no_significant_gap`` -- is marked in every answer ("your references disagree
with each other on Mx: ..."), and no verdict on it is stated as confident.

Example::

    >>> check = self_check(ref_flights, reference)
    >>> check.false_alarms, check.clean

Calibration
-----------

The reference model: the nominal parameter set calibrated on the reference flights, with
its residual statistics as the noise model of every later comparison.

A flight's gap is what it does that *this* model does not. Whatever every reference flight
shares -- the real thrust and drag factors, the command -> speed map, the motors' lag, rotor
drag, the real inertia, aerodynamic rate damping -- is absorbed here once, so it no longer
leaks into each flight's comparison (a 53 ms motor lag is then judged against the
references' own 7 ms, not against zero).

Stages
------
1. Static command -> speed map per rotor (:func:`quadsim.gap.residual.fit_motor_map`) on the
   references (commands logged).
2. One bounded least-squares fit (:func:`quadsim.gap.fitting.fit_candidate`, solved through
   the stacked residual's R factor: :func:`quadsim.gap.lsq.compact_least_squares`) of the shared
   parameters :data:`SHARED` on all reference flights together: relative b and d
   (``nominal_refit``; d by instrumental variables), the thrust curve's slope about their
   mean rotor speed where they determine it (:func:`centred_curve`, :func:`calibrate`), the
   rotor-drag coefficient, the relative inertia error xx, yy, zz, rate damping x, y, z, the
   rotors' spin inertia
   (gyroscopic torque) and, with commands, the motor time constant and, with a battery
   voltage log that varies (:data:`VBAT_TESTED`), the speed per command following
   vbat / V_full (the map "with lag and voltage"); a steady wind (vx, vy). Each is an
   effect every nominal flight may share, which a flight must not be named by.
   The rotor speeds' *timing* is shared too: the fit starts from the rotor speeds read
   d0 later (d0 the references' mean cross-correlation delay, :mod:`quadsim.logs.delays`),
   and up to :data:`REFINE_STEPS` pooled Levenberg-Marquardt steps (:func:`_refine`) then
   move every shared parameter and the timing offset d together (forward difference of 2
   ms; a shift is band-limited on the fit samples, :func:`aligned`). Why:
   the spin-up reaction torque ``-Jr sum_i s_i dOmega_i/dt`` fits the yaw channel only at
   the right timing, and the cross-correlation estimate reads that very torque as delay,
   so the timing and the rotors' spin inertia are found only together. A flight is
   compared with the reference model at d (:meth:`Reference.align`); its own timing
   differs from d by the evidence's nuisance delay or the reading ``signal_delay``.
   Values theta_ref and d; standard errors se_pool (the bounded fit's, correlation-widened)
   and se_d (the pooled information's).
   Where those steps read a roll or pitch inertia no plausible vehicle has
   (:func:`rotation_implausible`: outside -50 .. +100 %), the roll/pitch rotation
   (:data:`ROTATION`: inertia xx, yy, rate damping x, y) is refitted with every other shared
   value and the timing held (:func:`_rotation_steps`; and so are their per-flight values
   in stage 3), the roll and pitch residual read where the data determine the inertia
   (:class:`TorqueSide`): on the torque side (``M_meas - M_model``, N m of the candidate's
   inertia) and band-passed to the band where the rotors drive the body (:data:`BAND_HZ`,
   4-16 Hz, :mod:`quadsim.identify.rotation`'s). Why: on a real vehicle most of the rotors'
   roll/pitch torque below a few hertz balances aerodynamic moments the library does not
   model (blade flapping, the airframe's), and turns the body little; that part is an
   error on the torque side, uncorrelated with the body's acceleration. The evidence's form
   ``I (w_dot_meas - I_v^-1 M_model)`` regresses the acceleration on that torque, so such
   an error attenuates ``1 / I_v`` and the inertia grows until its bound (real Crazyflie
   references: +200 %, with the rate damping at 0); on the torque side, whole band, the
   same remainder dominates the cost; in the band the torque-side fit reads the inertia
   the rotors imply (docs/gap.md, known limits: measured). The refit is kept only where
   the band determines the rotation: a plausible inertia, and at least :data:`BAND_R2` of
   the band-passed body moment explained on roll and pitch (:func:`band_explained`, the
   acceptance of :mod:`quadsim.identify.rotation`'s band fit); else the whole band's
   values stay (generated logs of :func:`quadsim.logs.generate.generate_flight` whose
   rotor speeds carry 10 rad/s of noise: band R^2 -2.3 / -2.2; the real Crazyflie
   references 0.93 / 0.87). Yaw, the other shared values, the noise model (stage 4) and
   every later comparison keep the evidence's form. Why so narrow: the band reading needs
   the body to move in the band and the rotor timing to be right there; read on every
   reference set with every shared value moving, a 5.5 kg simulated quadrotor's
   references moved their rotor timing 0.1 -> 2.8 ms and their rate damping 0 ->
   0.015-0.026 N m s/rad and that source's inertia errors went unnamed; on generated
   references sharing a flapping moment, the yaw inertia and the timing moved and the set
   no longer judged itself clean (benchmarks/HISTORY.md, "The real references' inertia on the
   torque side in the band").
3. Between-flight scatter: one Gauss-Newton step from theta_ref on each reference flight
   alone gives that flight's value theta_j and standard error se_j; the scatter is the
   method-of-moments random-effect variance ``tau^2 = max(0, var_j(theta_j) - mean_j se_j^2)``.
   The *reference uncertainty* of a parameter is ``s_ref = sqrt(se_pool^2 + tau^2)``: what a
   new nominal flight may show (the pooled value is known to se_pool, a flight scatters by
   tau).
4. Noise model per channel c (Fx Fy Fz Mx My Mz in N, N m; rotor_1..R in rad/s): sigma_c =
   RMS of the calibrated model's residual over the reference flights (so a systematic model
   error all references share counts as "normal"), and the integrated autocorrelation time
   tau_c (samples at the fit rate, 1 + 2 sum rho_k up to the first rho < 0.05): a flight of
   N samples carries N_eff,c = N / tau_c independent samples on that channel.
5. Lack-of-fit statistics: per reference flight and channel the log of its mean squared
   residual over sigma_c^2; their mean per channel and a spread per channel moderated
   towards the channels' common one by their own scatter (:mod:`.reference`, the limma
   method; outside the references' envelope at least the pooled spread); a flight is
   compared with them in :mod:`.judge`.
6. Signal delays (:mod:`quadsim.logs.delays`): each signal's mean and spread over the
   references (ms).
7. Envelope (:mod:`.reference`): the references' RMS speed, body rate and thrust variation,
   and the trend of their own values (stage 3) and log mean squares (stage 5) along their
   main axis: how the model extrapolates to a flight flown beyond them.

Shared beyond :data:`SHARED` (:func:`per_flight_candidate`): the vertical drag (body drag
C_d A along body z) and, with commands but no voltage log, the motor map's gain
(:mod:`.speed_gain`). Both drift with how a flight is flown, so a nominal flight flown
slower or faster than the references must find its own value inside the reference
uncertainty, not in a reading.

The shared wind has a Gaussian prior (mean 0, :data:`quadsim.gap.fitting.WIND_SD_MS` = 5 m/s)
in the pooled steps (:func:`_refine`), and its standard error is the posterior's there: a
wind acts only through drag, so references without drag do not fix it, and a bounded fit
alone leaves it anywhere in its range, where every explanation that gave the drag a value
of its own would meet it.

Example::

    >>> ref = calibrate(prepare(nominal_logs, params), params)
    >>> ref.theta, ref.s_ref, ref.sigma        # shared values, their uncertainty, noise
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import norm

from ..core.errors import InputError, ModelError
from ..effects.base import EffectSet
from ..effects.battery_sag import VOLTAGE_TESTED
from ..effects.battery_sag import voltage_spread as battery_voltage_spread
from ..logs.zerophase import sosfiltfilt0
from ..vehicle.params import VehicleParams
from .fitting import (
    DETERMINED,
    WIND_SD_MS,
    Candidate,
    correlation_time,
    curve_slope_sd,
    fit_candidate,
    fit_motor_map,
    noise_floor,
    noise_scale,
    parameter_bounds,
    plausibility,
    residuals,
    start_off,
    typical_scales,
)
from .fitting import SPEED_GAIN_PART as SPEED_GAIN
from .logcheck import needs_pose
from .reference import (  # re-exported: the calibration's public names
    FD_STEP,
    MIN_FLIGHTS,
    MIN_SPREAD,
    Reference,
    aligned,
    centre_term,
    coordinates,
    envelope_of,
    excitation,
    fit_discrepancy,
    jacobian,
    moderated_spread,
    rotor_spectra,
    shifted,
    weighted_residual,
)
from .residual import load_exponent, measured_wrench, min_time_constant, proportional_rotors

__all__ = ["CALIBRATED_SCHEMA", "Calibrated", "code_version", "reference_key",
           "FALSE_ALARM_SHARE", "NUISANCE", "PRACTICAL_Z", "PerFlight", "SelfCheck", "Spread",
           "against_text", "band_share", "leave_one_out", "negligible", "placed", "self_check_of",
           "settled_self_check", "spreads", "to_refine",
           "FD_STEP",
           "MAX_SHIFT_S", "SHARED", "VBAT_TESTED", "Reference", "aligned", "bounded", "calibrate",
           "fit_bounds", "jacobian", "odd_references", "per_flight_candidate",
           "shared_candidate", "shifted",
           "voltage_spread", "weighted_residual"]


#: a reading's interval must lie beyond this many between-flight standard deviations of the
#: same reading on the references: their 95 % band (two-sided, normal)
PRACTICAL_Z = 2.0
#: the share of references a set may judge as not ``no_significant_gap`` and still be clean:
#: the rate the diagnosis promises on flights that differ in nothing (90 % clear)
FALSE_ALARM_SHARE = 0.1
#: parameter names (their ``.parameter`` part, or the whole name) that are never a
#: difference on their own: the rotor speeds' delay, a cable's swing at the first sample and
#: its damping, a propeller's speed exponent
NUISANCE = ("delay.rotor", "lean_x", "lean_y", "rate_x", "rate_y", "swing_damping", "alpha")


@dataclass(frozen=True)
class PerFlight:
    """Each reference flight's own fit, kept by the calibration
    (:func:`quadsim.gap.calibrate.calibrate`) so that the self-check can leave one out of
    what is built from them: ``coords`` (n, 3) the flights' envelope coordinates
    (:func:`quadsim.gap.reference.coordinates`), ``values`` and ``se`` (n, M) each flight's
    own shared values and their standard errors (one Gauss-Newton step from theta_ref),
    ``identified`` (M,) bool, ``info`` (n, M) the inverse information per sample (or
    None)."""

    coords: np.ndarray
    values: np.ndarray
    se: np.ndarray
    identified: np.ndarray
    info: np.ndarray | None
    #: (n, C') each flight's :func:`quadsim.gap.reference.excitation`; None: not measured
    excite: np.ndarray | None = None

    def scatter(self) -> np.ndarray:
        """(M,) method-of-moments between-flight spread of the shared values (their sample
        variance less the mean squared standard error, floored at 0)."""
        if len(self.values) < 2:
            return np.zeros(self.values.shape[1])
        return np.sqrt(np.clip(self.values.var(axis=0, ddof=1)
                               - (self.se ** 2).mean(axis=0), 0, None))

    def envelope(self, log_ms: np.ndarray):
        """The flights' :func:`quadsim.gap.reference.envelope_of`."""
        return envelope_of(self.coords, self.values, self.se, self.identified, log_ms,
                           info=self.info, excite=self.excite)

    def without(self, j: int) -> PerFlight:
        """The same without flight ``j``."""
        return PerFlight(np.delete(self.coords, j, 0), np.delete(self.values, j, 0),
                         np.delete(self.se, j, 0), self.identified,
                         None if self.info is None else np.delete(self.info, j, 0),
                         None if self.excite is None else np.delete(self.excite, j, 0))


@dataclass(frozen=True)
class Spread:
    """One parameter of one reading on the references (the parameter's SI unit): ``mean``
    of its fitted values over ``count`` reference flights, ``sd`` their *physical*
    between-flight standard deviation (their scatter less their own estimation noise: module
    doc, :meth:`of`), ``noise`` the RMS of their posterior SDs and ``mean_se`` the standard
    error of ``mean`` (0: a centre known exactly); ``edge``: how far beyond the references'
    outermost place (log units along their envelope axis) :func:`placed` moved it along
    their trend (0: at their own readings)."""

    mean: float
    sd: float
    count: int
    noise: float = 0.0
    mean_se: float = 0.0
    edge: float = 0.0

    @classmethod
    def of(cls, values, post_sd) -> Spread:
        """The spread of readings ``values`` (n >= 2) with posterior SDs ``post_sd``:
        ``sd`` = sqrt(max(var - mean(post_sd^2), min(1, sqrt(2 / (n - 1))) var)), ``var``
        = var(values, ddof 1) (method of moments, E var = tau^2 + mean s_i^2, floored at one
        standard error of ``var``: module doc), ``noise`` = sqrt(mean(post_sd^2)),
        ``mean_se`` = sqrt(var / n)."""
        v, s = np.asarray(values, float), np.asarray(post_sd, float)
        var, noise2 = float(v.var(ddof=1)), float(np.mean(s ** 2))
        floor = min(1.0, np.sqrt(2.0 / (len(v) - 1))) * var
        return cls(float(v.mean()), float(np.sqrt(max(var - noise2, floor))), len(v),
                   float(np.sqrt(noise2)), float(np.sqrt(var / len(v))))


@dataclass(frozen=True)
class SelfCheck:
    """The references judged against each other (module doc).

    ``flights``: the reference names; ``verdicts``: each one's verdict (same order);
    ``false_alarms``: (name, verdict, channels) of those not ``no_significant_gap``;
    ``spreads``: (explanation name, variant) -> parameter -> :class:`Spread`; ``slow``:
    (n, C) each judged reference's slow-part mean square under "no difference" against the
    others (:attr:`quadsim.gap.evidence.Evidence.slow`), the per-flight systematic
    remainder's normal (:func:`quadsim.gap.judge.remainder_of`); None: not measured;
    ``per``: each reference's :func:`readings` in the order of the reference model's
    envelope coordinates, what :func:`placed` places ``spreads`` with (empty: not kept, or
    already placed); ``timing``: (n,) each judged reference's log-evidence margin of a rotor
    lag over a rotor signal delay (:func:`timing_margin`; None: not measured), the margin
    two rotor forms have on flights that differ in nothing
    (:func:`quadsim.gap.judge.timing_rival`); ``confident``: the names of the false alarms
    whose verdict is stated as confident (a name or ``unexplained``, not tentative): a
    reference unlike the others beyond their spread (:func:`odd_references`)."""

    flights: tuple
    verdicts: tuple
    false_alarms: tuple
    spreads: dict
    slow: np.ndarray | None = None
    per: tuple = ()
    timing: np.ndarray | None = None
    confident: tuple = ()

    @property
    def clean(self) -> bool:
        """Whether at most :data:`FALSE_ALARM_SHARE` of the references are false alarms."""
        return len(self.false_alarms) <= FALSE_ALARM_SHARE * len(self.flights)

    def channels(self) -> list[str]:
        """The channels that drive the false alarms, most frequent first."""
        count: dict[str, int] = {}
        for _, _, chans in self.false_alarms:
            for c in chans:
                count[c] = count.get(c, 0) + 1
        return sorted(count, key=lambda c: (-count[c], c))

    def text(self) -> str:
        """The self-check in words (one sentence)."""
        n, k = len(self.flights), len(self.false_alarms)
        if not k:
            return f"Self-check: each of the {n} reference flights judged against the others " \
                   "comes out no_significant_gap."
        which = ", ".join(f"{name} ({verdict})" for name, verdict, _ in self.false_alarms[:4])
        more = f" and {k - 4} more" if k > 4 else ""
        chans = self.channels()
        on = f" on {', '.join(chans[:3])}" if chans else ""
        if self.clean:
            return (f"Self-check: {k} of the {n} reference flights judged against the others "
                    f"{'is' if k == 1 else 'are'} not no_significant_gap: {which}{more}.")
        return (f"Your references disagree with each other{on}: {k} of the {n}, judged "
                f"against the others, {'is' if k == 1 else 'are'} not no_significant_gap "
                f"({which}{more}); verdicts "
                "against them are not stated as confident.")

    def to_json(self) -> dict:
        """The self-check as JSON: flights, verdicts, false alarms, clean, and each
        reading's spread on the references."""
        return {"flights": list(self.flights), "verdicts": list(self.verdicts),
                "false_alarms": [{"flight": n, "verdict": v, "channels": list(c)}
                                 for n, v, c in self.false_alarms],
                "clean": self.clean, "channels": self.channels(),
                "confident": list(self.confident),
                "spreads": {f"{name}{' (' + variant + ')' if variant else ''}":
                            {p: [s.mean, s.sd, s.count, s.noise] for p, s in params.items()}
                            for (name, variant), params in self.spreads.items()}}


def leave_one_out(reference, j: int):
    """``reference`` without its ``j``-th flight where it is fitted from the flights'
    residuals (module doc): the discrepancy term, the lack-of-fit baseline, the
    between-flight scatter and the envelope (:class:`PerFlight`); the pooled shared
    parameters reused. ``reference`` itself where it keeps no per-flight data."""
    log_ms = getattr(reference, "log_ms", None)
    if log_ms is None or len(log_ms) < 3:
        return reference
    kept = np.delete(log_ms, j, axis=0)
    spread, dof, pooled = moderated_spread(kept)
    disc = reference.discrepancy
    out = dataclasses.replace(
        reference, discrepancy=None if disc is None else disc.without(j),
        lof_mean=kept.mean(axis=0), lof_sd=spread, lof_dof=dof, lof_pooled=pooled,
        log_ms=kept, names=[n for k, n in enumerate(reference.names) if k != j],
        self_check=None)
    per = getattr(reference, "per_flight", None)
    if per is not None:         # the between-flight scatter and the envelope without it
        per = per.without(j)
        out = dataclasses.replace(out, per_flight=per, scatter=per.scatter(),
                                  envelope=per.envelope(kept))
    return out


def _own(key: str, name: str = "") -> bool:
    """Whether parameter ``key`` (``effect.parameter``) can be a difference on its own in
    reading ``name``: not a :data:`NUISANCE` key, except the rotor speeds' timing in the
    reading that is that timing (``signal_delay``: every other explanation fits
    ``delay.rotor`` as a nuisance, this one reads it as the flight's difference, so its size
    is compared with the references' own readings of it as every other reading's is)."""
    if name == "signal_delay" and key == "delay.rotor":
        return True
    return key not in NUISANCE and key.split(".")[-1] not in NUISANCE


def readings(rows) -> dict:
    """(name, variant) -> parameter -> (value, posterior SD) of one flight's Evidence
    ``rows``: the explanations' own parameters that flight determines (an undetermined value
    sits at its prior's centre on every flight: no spread of the references' own), of the
    readings fitted to convergence (a screened one keeps its one linear step from the prior's
    centre, :mod:`quadsim.gap.evidence`: not the flight's value), nuisance ones left out."""
    return {(ev.name, ev.explanation.variant): {k: (float(v), float(ev.post_sd[k]))
                                               for k, v in ev.values.items()
                                               if _own(k, ev.name) and ev.determined.get(k)}
            for ev in rows if ev.name != "no_difference" and not getattr(ev, "screened", False)}


def spreads(per_flight: list[dict]) -> dict:
    """(name, variant) -> parameter -> :class:`Spread` (:meth:`Spread.of`) over flights'
    :func:`readings` (at least two flights per parameter)."""
    out: dict = {}
    for key in {k for r in per_flight for k in r}:
        params: dict = {}
        for p in {q for r in per_flight for q in r.get(key, {})}:
            pairs = [r[key][p] for r in per_flight if p in r.get(key, {})]
            if len(pairs) >= 2:
                params[p] = Spread.of([v for v, _ in pairs], [s for _, s in pairs])
        if params:
            out[key] = params
    return out


def _interval(ev, key: str, s: Spread) -> float:
    """The 95 % half-width of reading ``ev``'s parameter ``key`` less the references' mean
    ``s.mean``: 1.96 sqrt(sd_post^2 + se_mean^2)."""
    return 1.96 * float(np.hypot(ev.post_sd[key], s.mean_se))


def negligible(ev, check: SelfCheck | None) -> bool:
    """Whether reading ``ev`` (an Evidence) is no difference that matters (module doc): none
    of its own determined parameters lies, with its 95 % interval, beyond
    :data:`PRACTICAL_Z` physical between-flight standard deviations of the same reading on
    the references: ``|v - mean| - 1.96 sqrt(sd_post^2 + se_mean^2) > PRACTICAL_Z sd``.
    False without a self-check or without the reading's spread on the references (nothing to
    compare with: the statistical rule alone)."""
    if check is None or ev.name == "no_difference":
        return False
    spread = check.spreads.get((ev.name, ev.explanation.variant))
    if not spread:
        return False
    compared = False
    for key, ok in ev.determined.items():
        if not ok or not _own(key, ev.name) or key not in spread:
            continue
        s = spread[key]
        compared = True
        if abs(ev.values[key] - s.mean) - _interval(ev, key, s) > PRACTICAL_Z * s.sd:
            return False
    return compared


def band_share(ev, check: SelfCheck | None) -> float:
    """The posterior probability (0-1) that reading ``ev`` (an Evidence) lies within the
    references' band of the same reading: for each of its own determined parameters with a
    spread on the references, the mass of its posterior N(v, sd_post^2 + se_mean^2) (the
    spread :func:`negligible`'s interval is 1.96 of) inside mean +- :data:`PRACTICAL_Z` sd,
    multiplied over the parameters (as if independent); 1.0 where :func:`negligible` has
    nothing to compare with (it then says False: the statistical rule alone).

    What it is for: :func:`negligible` calls a reading no difference that matters where its
    95 % interval does not lie beyond the band, which includes a reading whose interval is
    wider than the band and reaches beyond it: the data do not tell whether it lies within
    (an "indeterminate" reading; equivalence needs the interval inside the band: Schuirmann's
    two one-sided tests, Kruschke's region of practical equivalence). This share is how much
    of such a reading's weight the data carry as "within the band"
    (:func:`quadsim.gap.judge.sure_null`)."""
    if check is None or ev.name == "no_difference":
        return 1.0
    spread = check.spreads.get((ev.name, ev.explanation.variant))
    if not spread:
        return 1.0
    share = 1.0
    for key, ok in ev.determined.items():
        if not ok or not _own(key, ev.name) or key not in spread:
            continue
        s = spread[key]
        scale = float(np.hypot(ev.post_sd[key], s.mean_se))
        if scale <= 0:
            inside = abs(ev.values[key] - s.mean) <= PRACTICAL_Z * s.sd
            share *= float(inside)
            continue
        hi = (s.mean + PRACTICAL_Z * s.sd - ev.values[key]) / scale
        lo = (s.mean - PRACTICAL_Z * s.sd - ev.values[key]) / scale
        share *= float(max(0.0, norm.cdf(hi) - norm.cdf(lo)))
    return share


def against_text(ev, check: SelfCheck | None, unit_of=lambda key: "") -> str:
    """The size of reading ``ev`` against the references' own readings of it, in words
    (module doc): per own determined parameter with a spread on the references, "mass
    +0.0066 kg against the references' +1e-05 ± 3e-05 kg (220 SDs)" (± their physical
    flight-to-flight SD); where they vary no more than their own estimation noise (``sd``
    0), "mass +0.0066 kg against the references' +1e-05 kg, which vary no more than their
    estimation noise (± 4e-05 kg): 95 % interval of the difference +0.0066 ± 0.0002 kg";
    placed beyond the references (:func:`placed`), "against the references' (on their
    trend, at this flight's place beyond them) ...";
    "" where there is nothing to compare with. ``unit_of(key)``: the parameter's unit."""
    if check is None:
        return ""
    spread = check.spreads.get((ev.name, ev.explanation.variant), {})
    parts = []
    for key, ok in ev.determined.items():
        if not ok or not _own(key, ev.name) or key not in spread:
            continue
        # the rotor speeds' timing in milliseconds, as the reading words it
        k, unit, label = ((1e3, "ms", "timing") if key == "delay.rotor"
                          else (1.0, unit_of(key), key.split(".", 1)[1]))
        s, v = spread[key], k * ev.values[key]
        mean, sd, noise = k * s.mean, k * s.sd, k * s.noise
        unit = f" {unit}" if unit and unit != "1" else ""
        head = f"{label} {v:+.3g}{unit} against the references' "
        if s.edge > 0:
            head += "(on their trend, at this flight's place beyond them) "
        if s.sd > 0:
            size = abs(ev.values[key] - s.mean) / s.sd
            parts.append(f"{head}{mean:+.2g} ± {sd:.2g}{unit} ({size:.3g} SDs)")
        else:
            parts.append(f"{head}{mean:+.2g}{unit}, which vary no more than their estimation "
                         f"noise (± {noise:.2g}{unit}): 95 % interval of the difference "
                         f"{v - mean:+.2g} ± {k * _interval(ev, key, s):.2g}{unit}")
    return "; ".join(parts)


def self_check_of(names: list, rows_list: list, judge_fn) -> SelfCheck:
    """The :class:`SelfCheck` of reference flights ``names`` from each one's Evidence rows
    against the leave-one-out reference (``rows_list[j]``: flight j's rows, or None where it
    could not be judged). ``judge_fn(j, check)`` judges flight j with ``check`` (the
    references' readings without flight j) and returns its
    :class:`~quadsim.gap.result.Verdict` (``outcome``, ``name``, ``lack_of_fit``,
    ``differ_on``)."""
    per = [readings(rows) if rows is not None else {} for rows in rows_list]
    verdicts, alarms, confident = [], [], []
    for j, name in enumerate(names):
        if rows_list[j] is None:
            verdicts.append("refused")
            continue
        others = SelfCheck(tuple(names), (), (), spreads(per[:j] + per[j + 1:]),
                           per=tuple(per[:j] + per[j + 1:]))
        verdict = judge_fn(j, others)
        verdicts.append(verdict.name)
        if verdict.outcome != "no_significant_gap":
            chans = tuple(verdict.lack_of_fit or {}) or tuple(verdict.differ_on or ())
            alarms.append((name, verdict.name, chans))
            if not getattr(verdict, "tentative", True):
                confident.append(name)
    nulls = [next((ev for ev in rows if ev.name == "no_difference"), None)
             for rows in rows_list if rows is not None]
    slow = [ev.slow for ev in nulls if ev is not None and ev.slow is not None]
    timing = [timing_margin(rows) for rows in rows_list if rows is not None]
    timing = [m for m in timing if m is not None]
    return SelfCheck(tuple(names), tuple(verdicts), tuple(alarms), spreads(per),
                     np.array(slow) if slow else None, tuple(per),
                     np.array(timing) if len(timing) == len(names) else None,
                     tuple(confident))


def odd_references(check: SelfCheck | None) -> tuple:
    """The names of the references to leave out of a set and calibrate again without: those the
    self-check ``check`` judges against the others with a verdict stated as confident
    (``check.confident``: a name or ``unexplained``, not tentative), where the set is
    otherwise clean -- at most :data:`FALSE_ALARM_SHARE` of it false alarms. Why: such a
    reference differs from the others beyond their own spread (its reading passed practical
    significance against theirs, or its residual stays beyond theirs), e.g. a payload flight
    given by mistake among nominal ones; kept, what it carries passes for normal and shifts
    the shared model every flight is judged against (docs/gap.md, "The self-check"). Only
    from a clean set: there the verdicts are stated as confident already, and leaving the
    odd one out removes what it would pass for normal without raising any confidence; a set
    that is not clean has its doubt stated in every answer, which leaving one out would
    lift. A set with more false alarms disagrees with itself and is marked so instead
    (:attr:`SelfCheck.clean`); a set of fewer than 1 / FALSE_ALARM_SHARE = 10 references has
    no room for one, so at least 9 stay (more than the discrepancy term's 5). () where none
    is left out."""
    if check is None or not check.clean:
        return ()
    return tuple(check.confident)


def to_refine(names: list, rows_list: list, check: SelfCheck) -> set:
    """The readings (explanation names) to read on every reference before ``check`` (of
    references ``names``, Evidence ``rows_list``, :func:`self_check_of`) is final: each
    reading a false alarm's rows fitted to convergence (not ``screened``, "no difference"
    aside), i.e. every reading the screen found within its cut there and so able to weigh
    in that reference's verdict (:mod:`quadsim.gap.evidence`, "Cut")."""
    alarmed = {n for n, _, _ in check.false_alarms}
    return {ev.name for n, rows in zip(names, rows_list) if n in alarmed and rows is not None
            for ev in rows if ev.name != "no_difference" and not getattr(ev, "screened", False)}


def _judge_item(items: list, judge_of, j: int, check):
    """``judge_of(items[j], check)`` (:func:`settled_self_check`'s judge of reference j)."""
    return judge_of(items[j], check)


def settled_self_check(names: list, items: list, *, rows_of, judge_of, refine) -> SelfCheck:
    """:func:`self_check_of` with every reading a false alarm weighs read on every reference
    (:func:`to_refine`), repeated until no alarm adds one.

    Why: a reference's practical-significance scale is the other references' readings
    (:func:`readings`), and a screened reading is none (its one linear step is not the
    flight's value). The screen leaves a reading screened where it cannot weigh in that
    flight's own verdict, so the scale held only the references where the reading happened
    to matter: with fewer than 2 there it has no scale at all (:func:`negligible` False,
    the statistical rule alone), and which ones those are moves with the pooled shared values
    (an alarm a full judgment does not raise; docs/gap.md, "The self-check"). Fitting only
    the alarmed references' readings keeps the check cheap where it is clean (no alarm:
    nothing refitted).

    ``items``: one per reference (None: not judged); ``rows_of(item)``: its Evidence rows;
    ``judge_of(item, check)``: its :class:`~quadsim.gap.result.Verdict` with ``check``;
    ``refine(item, wanted)``: the item with its screened rows of the readings named in
    ``wanted`` fitted to convergence."""
    done: set = set()
    items = list(items)
    while True:
        rows_list = [None if it is None else rows_of(it) for it in items]
        check = self_check_of(list(names), rows_list,
                              functools.partial(_judge_item, items, judge_of))
        wanted = to_refine(list(names), rows_list, check) - done
        if not wanted:
            return check
        done |= wanted
        items = [None if it is None else refine(it, wanted) for it in items]


def timing_margin(rows) -> float | None:
    """One flight's log-evidence margin (natural log) of its best-supported ``motor_lag``
    row over its best ``signal_delay`` row (Evidence ``rows``); None without both."""
    best: dict = {}
    for ev in rows:
        if ev.name in ("motor_lag", "signal_delay"):
            best[ev.name] = max(best.get(ev.name, -np.inf), float(ev.log_z))
    if len(best) < 2:
        return None
    return best["motor_lag"] - best["signal_delay"]


def placed(check: SelfCheck | None, reference) -> SelfCheck | None:
    """``check`` with each reading's :class:`Spread` at the place of the flight that
    ``reference`` is placed at (``reference.place``,
    :func:`quadsim.gap.reference.local_reference`): unchanged inside the references' range
    of places; beyond it by e (log units along the envelope axis) the trend of that reading
    over the references (module doc, "At the flight's place": mean + b e, mean_se^2 +
    var(b) e^2, sd^2 + (b^2 + var(b)) e^2), the references' places u_i = coords_i . axis of
    ``reference.envelope``. ``check`` itself without a place, a trend, kept readings
    (``per``) or one reading per envelope coordinate; the result keeps no readings (placed
    once)."""
    place = getattr(reference, "place", None)
    envelope = getattr(reference, "envelope", None)
    trend = getattr(envelope, "trend", None)
    if check is None or not check.per or place is None or trend is None \
            or getattr(place, "u", None) is None or len(envelope.coords) != len(check.per):
        return check
    edge = float(place.u - np.clip(place.u, trend.u_low, trend.u_high))
    if edge == 0.0:
        return check
    u = np.asarray(envelope.coords, float) @ trend.axis
    out: dict = {}
    for key, params in check.spreads.items():
        out[key] = {}
        for p, s in params.items():
            have = [j for j, r in enumerate(check.per) if p in r.get(key, {})]
            out[key][p] = _spread_at(s, u[have], np.array([check.per[j][key][p][0]
                                                           for j in have]), edge)
    return dataclasses.replace(check, spreads=out, per=())


def _spread_at(s: Spread, u: np.ndarray, v: np.ndarray, edge: float) -> Spread:
    """Spread ``s`` of readings ``v`` at places ``u`` moved ``edge`` beyond the outermost
    reference along their trend (:func:`placed`); ``s`` where no trend is measured."""
    if len(u) < MIN_FLIGHTS or np.ptp(u) < MIN_SPREAD:
        return s
    du = u - u.mean()
    s_uu = float(du @ du)
    b = float(du @ (v - v.mean())) / s_uu
    rest = v - v.mean() - b * du
    var_b = float(rest @ rest) / (len(v) - 2) / s_uu
    return dataclasses.replace(
        s, mean=s.mean + b * edge, mean_se=float(np.hypot(s.mean_se, np.sqrt(var_b) * edge)),
        sd=float(np.sqrt(s.sd ** 2 + (b ** 2 + var_b) * edge ** 2)), edge=abs(edge))


#: shared parameter groups (effect, fitted parameters); motor_lag only with commands.
SHARED = (("nominal_refit", ("thrust", "drag")),
          ("thrust_curve", ("linear", "quadratic")),
          ("rotor_drag", ("coefficient",)),
          ("inertia_error", ("xx", "yy", "zz")),
          ("rate_damping", ("x", "y", "z")),
          ("gyroscopic", ("rotor_inertia",)),
          ("wind", ("vx", "vy")),
          ("motor_lag", ("time_constant",)),
          ("battery_sag", ("full_voltage",)))

#: groups that need logged commands (they act on the command -> speed channel) ...
NEEDS_COMMANDS = {"motor_lag", "battery_sag"}
#: ... and a logged battery voltage (the speed per command follows vbat / V_full).
NEEDS_VBAT = {"battery_sag"}

#: the references test the law "speed per command ~ vbat / V_full" only where their logged
#: voltage varies by at least this fraction of its mean (:func:`voltage_spread`;
#: :data:`quadsim.effects.battery_sag.VOLTAGE_TESTED`, 1 %). Below it the law's slope is
#: untested and V_full is only the motor map's gain, so the reference model takes the gain
#: (:mod:`.speed_gain`) and a flight's own sag is a reading
#: (:func:`quadsim.gap.explanations.explanations_for`).
VBAT_TESTED = VOLTAGE_TESTED


def voltage_spread(flights) -> tuple[float, float]:
    """(mean, relative spread) of the flights' logged battery voltage (V, fraction):
    :func:`quadsim.effects.battery_sag.voltage_spread` of their fit states' voltages."""
    return battery_voltage_spread([getattr(f, "fit", f).vbat for f in flights])


#: the rotor speeds' timing offset is searched within this (s) of zero: the lag window of
#: :data:`quadsim.logs.delays.MAX_LAG_S`.
MAX_SHIFT_S = 0.1
#: finite-difference step (s) of the timing offset and its typical size (the LM ridge unit):
#: a fifth of a 100 Hz fit sample, and the 10 ms that real logs carry (module doc).
SHIFT_STEP_S, SHIFT_TYPICAL_S = 0.002, 0.01


def shared_candidate(rotor: bool, vbat: bool = False, *, pose: bool = True) -> Candidate:
    """The shared parameters as one candidate: :data:`SHARED` less the groups the logs
    cannot show (no commands: motor lag and battery; no voltage: battery; no pose: the
    effects that read it, :func:`quadsim.gap.logcheck.needs_pose`)."""
    parts = tuple((name, {}, fitted) for name, fitted in SHARED
                  if (rotor or name not in NEEDS_COMMANDS) and (vbat or name not in NEEDS_VBAT)
                  and (pose or not needs_pose([(name, {}, fitted)])))
    return Candidate("reference", parts)


#: the vertical air drag every flight meets (stage 2): body drag C_d A along body z. Not the
#: sideways part: it is nearly collinear with the rotor drag on the references' speeds, and
#: sharing both widened the rotor drag's reference uncertainty until a flight with 4x the
#: references' rotor drag was judged "no difference" (tests/test_evidence.py).
BODY_DRAG = ("body_drag", {}, ("cd_area_vertical",))


def per_flight_candidate(rotor: bool, vbat: bool = False, *, pose: bool = True) -> Candidate:
    """The shared parameters of the per-flight reference model: :func:`shared_candidate`
    plus the vertical drag (:data:`BODY_DRAG`) and, with commands but no voltage log,
    the motor map's gain (:mod:`.speed_gain`; with a voltage log
    ``battery_sag.full_voltage`` is that gain). Both change with how a flight is flown
    (module doc, stage 2), so a flight's own value must have a place in the reference
    uncertainty; neither is a reading of its own (a flight's body drag is, on top)."""
    cand = shared_candidate(rotor, vbat, pose=pose)
    extra = ((BODY_DRAG,) if pose else ()) + ((SPEED_GAIN,) if rotor and not vbat else ())
    return Candidate(cand.name, cand.parts + extra, cand.base)


def centred_curve(cand: Candidate, states) -> Candidate:
    """``cand`` with the shared thrust curve's slope taken about the flights' mean rotor
    speed (``thrust_curve.centre``, rad/s): the slope then moves the thrust only away from
    the references' hover, and b alone sets it there.

    Why: the references fit b and a linear term ``l Omega`` together; over their narrow
    band of rotor speeds the two are nearly collinear. About zero speed each is uncertain
    alone, and each shared parameter is marginalised with its own spread: the hover thrust
    could move by that spread, and a mass would be "no difference". Without speeds logged,
    the slope is kept about zero and the curvature dropped."""
    speeds = [np.mean(s.rotor_speed) for s in states if s.rotor_speed is not None]
    if not speeds:      # no speeds logged: a slope about zero only (no hover to centre on)
        return Candidate(cand.name, tuple(
            (name, fixed, tuple(p for p in fitted if p != "quadratic"))
            if name == "thrust_curve" else (name, fixed, fitted)
            for name, fixed, fitted in cand.parts), cand.base)
    centre = float(np.mean(speeds))
    parts = tuple((name, {**fixed, "centre": centre} if name == "thrust_curve" else fixed,
                   fitted) for name, fixed, fitted in cand.parts)
    return Candidate(cand.name, parts, cand.base)


def _covariance(info: np.ndarray, typical: np.ndarray) -> np.ndarray:
    """The (pseudo-)inverse of the information ``info`` taken in units of each parameter's
    typical size ``typical`` (P,): ``T (T info T)^+ T`` (P, P). In SI units the information
    of a rotor inertia (~1e-6 kg m^2) is ~1e24 times a wind's (m/s), so a pseudo-inverse
    there cuts the wind's direction as round-off and gives it a variance of 0."""
    t = np.asarray(typical, dtype=float)
    return t[:, None] * np.linalg.pinv(info * np.outer(t, t)) * t[None, :]


#: shared parameters the references fix only together (pooled), never flight by flight: they
#: stay at the pooled value in each flight's one-step estimate (:func:`_scatter`), with no
#: between-flight scatter and the pooled standard error as their spread. The thrust curve's
#: curvature about the hover: a flight's own rotor speeds spread too little to fix it, and
#: it is a property of the propeller, not of how a flight is flown (left free, one flight's
#: curvature moves with its roll/pitch inertia).
POOLED = ("thrust_curve.quadratic",)


def _scatter(flights, reference: Reference, own: list | None = None) -> np.ndarray:
    """Method-of-moments between-flight variance of each shared parameter (module doc,
    stage 3): one Gauss-Newton step per reference flight from theta_ref. ``own``: a list
    that receives (values (n, P), standard errors (n, P)), each flight's own estimate.

    The step's pseudo-inverse is taken in SI units (not :func:`_covariance`): there it cuts
    the directions one flight's data barely fix (a wind without drag, inertia against
    damping), which then stay at theta_ref instead of moving per flight."""
    return _scatters(flights, reference, [own])[0]


def _scatters(flights, reference: Reference, owns: list, side: TorqueSide | None = None,
              *, pooled: list | None = None) -> list[np.ndarray]:
    """:func:`_scatter` of ``reference`` (into ``owns[0]``) and, with ``side``, of
    ``reference`` with that torque side (into ``owns[1]``), flight by flight: the side's
    Jacobian from the plain one's columns (:func:`_side_jacobian`). Returns the scatters.
    ``pooled``: a list that receives each channel's information summed over the flights
    ((C, P', P'): the plain Jacobians' rows of that channel, ``sum_j J_jcᵀ J_jc``, the
    columns not in :data:`POOLED`)."""
    k = len(reference.theta)
    free = [j for j, n in enumerate(reference.candidate.parameter_names) if n not in POOLED]
    turned = None if side is None else dataclasses.replace(reference, side=side)
    steps: list = [([], []) for _ in range(1 if side is None else 2)]
    for f in flights:
        jac, r = jacobian(f, reference, free, reference.candidate.effects, with_base=True)
        pairs = [(jac, r)]
        if turned is not None:
            pairs.append(_side_jacobian(f, turned, free, (jac, r)))
        for step, ((values, variances), (jac, r)) in enumerate(zip(steps, pairs)):
            info = jac.T @ jac
            if pooled is not None and step == 0:
                cube = jac.reshape(-1, len(reference.sigma), jac.shape[1])
                mine = np.einsum("ncp,ncq->cpq", cube, cube)
                pooled[:] = [mine if not pooled else pooled[0] + mine]
            cov = np.linalg.pinv(info)
            value, variance = reference.theta.copy(), np.asarray(reference.se_pool, float) ** 2
            value[free] -= cov @ (jac.T @ r)
            variance[free] = np.clip(np.diag(cov), 0, None)
            values.append(value)
            variances.append(variance)
    out = []
    for own, (values, variances) in zip(owns, steps):
        values, variances = np.asarray(values), np.asarray(variances)
        if own is not None:
            own.extend([values, np.sqrt(variances)])
        out.append(np.zeros(k) if len(values) < 2 else np.sqrt(
            np.clip(values.var(axis=0, ddof=1) - variances.mean(axis=0), 0, None)))
    return out


def _side_jacobian(states, reference: Reference, free: list[int], plain: tuple):
    """:func:`quadsim.gap.reference.jacobian` (with its base) of ``reference``, whose roll and
    pitch residual is on the torque side (``reference.side``, a :class:`TorqueSide`), on one
    flight's ``states``, from ``plain`` = (Jacobian, weighted residual) of the same columns
    ``free`` at the same theta_ref without the side.

    The side replaces the residual's channels 3 + ``axes`` by ``L(r) = band(r[:, 3:6] B)``,
    ``B = (I^-1 I_v)[:, axes]`` with ``I_v`` the vehicle's inertia, and leaves the others as
    they are; for a parameter that does not move ``I_v``, ``L`` is the same linear map at
    the base and at the probe, so the forward difference of ``L(r)`` is ``L`` of the forward
    difference of ``r``: the plain column (its weight taken off) through ``L``, weighted
    again; the other channels are the plain column's own. A column that moves ``I_v`` (the
    inertia) is probed as before. The same numbers to the differences' round-off (1e-16 of
    the residual over the step; tests/test_side_scatter.py) without the probes' residuals."""
    side = reference.side
    params = reference.params
    memo: dict = {}
    effects = reference.candidate.effects(reference.theta)
    base = weighted_residual(states, reference, effects, memo).ravel()
    inertia = np.asarray(EffectSet(tuple(effects)).apply_to_params(params).inertia, float)
    typical = typical_scales(reference.candidate, params)
    linear, probed = [], []
    for col, j in enumerate(free):
        theta = reference.theta.copy()
        theta[j] += FD_STEP * typical[j]
        try:
            moved = EffectSet(tuple(reference.candidate.effects(theta))).apply_to_params(params)
            same = np.array_equal(np.asarray(moved.inertia, float), inertia)
        except ModelError:
            same = False
        (linear if same else probed).append(col)
    jac_plain = plain[0]
    weight = np.sqrt(reference.weights)
    chans = len(weight)
    jac = np.array(jac_plain, dtype=float, copy=True)
    if linear:
        cube = jac.reshape(-1, chans, len(free))[:, :, linear]     # (N, C, k) a view's copy
        back = np.linalg.solve(np.asarray(params.inertia, float), inertia)[:, list(side.axes)]
        moment = np.einsum("nik,ia->nak", cube[:, 3:6, :] / weight[3:6][None, :, None], back)
        banded = side.band(moment.reshape(len(moment), -1)).reshape(moment.shape)
        cols = [3 + a for a in side.axes]
        cube[:, cols, :] = banded * weight[cols][None, :, None]
        view = jac.reshape(-1, chans, len(free))
        view[:, :, linear] = cube
    if probed:
        jac[:, probed] = jacobian(states, reference, [free[c] for c in probed],
                                  reference.candidate.effects, memo=memo, base=base)
    return jac, base


#: at most this many pooled Levenberg-Marquardt steps after the bounded fit (:func:`_refine`);
#: they stop earlier once a step lowers the pooled -2 log L by less than :data:`REFINE_TOL`
#: (0.1: a twentieth of a log-likelihood unit, far below any evidence the judge weighs).
REFINE_STEPS = 8
REFINE_TOL = 0.1


class _Views:
    """The fit views of prepared flights at any rotor timing: :func:`aligned`'s states, each
    flight's rotor spectra (:func:`rotor_spectra`) computed once for all the timings the
    refinement reads (the same numbers: :func:`shifted` with the spectra it would compute)."""

    #: the views kept per flight: the last few timings read (a refinement step reads its
    #: timing, that plus the difference step, and the trials'; the next step starts at one)
    KEPT = 4

    def __init__(self, flights):
        self.fits = [getattr(f, "fit", f) for f in flights]
        self.spectra: list = [None] * len(self.fits)
        self.read: list[dict] = [{} for _ in self.fits]

    def __len__(self) -> int:
        return len(self.fits)

    def at(self, i: int, delay_s: float):
        """Flight ``i``'s fit states with its rotor speeds read ``delay_s`` (s) later (the
        same object for a timing read again while kept: the same numbers)."""
        fit = self.fits[i]
        if delay_s == 0.0 or fit.rotor_speed is None:
            return fit
        kept = self.read[i]
        view = kept.get(float(delay_s))
        if view is None:
            if self.spectra[i] is None:
                self.spectra[i] = rotor_spectra(fit)
            view = kept[float(delay_s)] = shifted(fit, delay_s, self.spectra[i])
            if len(kept) > self.KEPT:
                del kept[next(iter(kept))]
        return view


def _pooled(views: _Views, probe, shift: float, timing: bool, bases: list | None = None):
    """Summed information JᵀJ, gradient Jᵀr and cost |r|^2 over the flights at ``shift``;
    with ``timing`` the last column is the rotor timing offset's (forward difference).
    ``bases``: each flight's weighted residual there (flattened) where already computed
    (:func:`_cost` of the step that moved here)."""
    k = len(probe.theta)
    size = k + int(timing)
    info, grad, cost = np.zeros((size, size)), np.zeros(size), 0.0
    for i in range(len(views)):
        view = views.at(i, shift)
        memo: dict = {}
        jac, r = jacobian(view, probe, list(range(k)), probe.candidate.effects, memo=memo,
                          with_base=True, base=None if bases is None else bases[i])
        if timing:
            later = weighted_residual(views.at(i, shift + SHIFT_STEP_S), probe,
                                      probe.effects(), memo).ravel()
            jac = np.column_stack([jac, (later - r) / SHIFT_STEP_S])
        info += jac.T @ jac
        grad += jac.T @ r
        cost += float(r @ r)
    return info, grad, cost


def fit_bounds(cand: Candidate, params: VehicleParams, dt: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of ``cand``'s parameters in the references' fit: the effects' plausible
    ranges, and a motor lag of at least a quarter of a fit sample ``dt`` (s), the Heun
    sub-step of the rotor channel (:func:`quadsim.gap.residual.min_time_constant`)."""
    lower, upper = parameter_bounds(cand, params)
    for k, name in enumerate(cand.parameter_names):
        if name == "motor_lag.time_constant":
            lower[k] = max(lower[k], min_time_constant(dt))
    return lower, upper


def bounded(cand: Candidate, params: VehicleParams, theta: np.ndarray, dt: float
            ) -> dict[str, str]:
    """Parameter -> "lower" or "upper" where ``theta`` sits at that bound of
    :func:`fit_bounds` (within 1e-9 of the parameter's typical size): a motor lag at a
    quarter of a fit sample (the shortest the fit resolves), an inertia at the end of its
    plausible range."""
    lower, upper = fit_bounds(cand, params, dt)
    tol = 1e-9 * typical_scales(cand, params)
    return {name: side for k, name in enumerate(cand.parameter_names)
            for side, hit in (("lower", theta[k] <= lower[k] + tol[k]),
                              ("upper", theta[k] >= upper[k] - tol[k])) if hit}


def _cost(views: _Views, probe, theta, shift: float) -> tuple[float, list | None]:
    """(|r|^2 summed over the flights, each flight's weighted residual r flattened) at
    ``theta`` and ``shift``; (inf, None) where ``theta`` leaves the physical set."""
    try:
        effects = probe.candidate.effects(theta)
        full = [weighted_residual(views.at(i, shift), probe, effects)
                for i in range(len(views))]
    except ModelError:          # e.g. an inertia breaking the triangle inequality: a wall
        return float("inf"), None
    return float(sum(np.sum(r ** 2) for r in full)), [r.ravel() for r in full]


def _refine(flights, params, rotor: bool, cand: Candidate, theta: np.ndarray, *,
            shift: float, sigma: np.ndarray, views: _Views | None = None,
            side: TorqueSide | None = None):
    """Pooled Levenberg-Marquardt steps from the bounded fit, summing each flight's
    information, over the shared parameters and the rotor speeds' timing offset (module
    doc, stage 2). The bounded fit stops after a few dozen evaluations of 12-14
    parameters at a fixed timing; the timing and the rotors' spin inertia are found only
    together (module doc, stage 2). Steps in units of each parameter's typical size with
    a ridge lambda (1 at the start; /3 after a step that lowers the cost, x4 and retried
    after one that does not), clipped to the bounds.
    ``views``: the flights' :class:`_Views` where the caller keeps them; ``side``: the
    roll and pitch residual's :class:`TorqueSide` (module doc, stage 2), None: as the
    evidence's.
    Returns (theta, shift, standard error of the shift, the wind's standard errors)."""
    dt = float(getattr(flights[0], "fit", flights[0]).t[1]
               - getattr(flights[0], "fit", flights[0]).t[0])
    lower, upper = fit_bounds(cand, params, dt)
    typical = typical_scales(cand, params)
    timing = all(getattr(f, "fit", f).rotor_speed is not None for f in flights)
    if timing:
        lower, upper = np.append(lower, -MAX_SHIFT_S), np.append(upper, MAX_SHIFT_S)
        typical = np.append(typical, SHIFT_TYPICAL_S)
    probe = Reference(params, rotor, cand, theta.copy(), np.zeros_like(theta),
                      np.zeros_like(theta), sigma, np.ones_like(sigma),
                      np.zeros_like(sigma), 1.0, 1, {}, [], {}, side=side)
    x = np.append(theta, shift) if timing else theta.copy()
    k = len(theta)
    # the steady wind's Gaussian prior (mean 0, WIND_SD_MS): a wind acts only through drag,
    # so with no drag to act through the data do not fix it and the bounded fit leaves it
    # anywhere; an explanation that then gives the drag a value of its own would meet it.
    # The prior takes such a wind to 0; a wind the data fix moves by (s / 5 m/s)^2 of itself.
    prior = np.array([1.0 / WIND_SD_MS ** 2 if n.startswith("wind.") else 0.0
                      for n in cand.parameter_names] + [0.0] * int(timing))
    lam, info, bases = 1.0, None, None
    views = _Views(flights) if views is None else views
    for _ in range(REFINE_STEPS):
        probe.theta = x[:k].copy()
        info, grad, cost = _pooled(views, probe, float(x[k]) if timing else 0.0, timing,
                                   bases)
        info, grad = info + np.diag(prior), grad + prior * x
        cost += float(np.sum(prior * x ** 2))
        def cost_at(trial):
            new, moved = _cost(views, probe, trial[:k], float(trial[k]) if timing else 0.0)
            return new + float(np.sum(prior * trial ** 2)), moved

        step = _damped_step(x, info, grad, cost, lam=lam, typical=typical,
                            bounds=(lower, upper), cost_at=cost_at)
        if step is None:
            break
        x, new, lam, bases = step
        if cost - new < REFINE_TOL:
            break
    cov = _covariance(info, typical)
    se = float(np.sqrt(max(cov[-1, -1], 0.0))) if timing else 0.0
    # the wind's standard error under its prior at the refined values (the bounded fit's is
    # that of a wind at its bound, ~0): what the references know of the room's wind
    wind_se = {n: float(np.sqrt(max(cov[j, j], 0.0)))
               for j, n in enumerate(cand.parameter_names) if n.startswith("wind.")}
    return x[:k], (float(x[k]) if timing else 0.0), se, wind_se


#: the shared parameters the torque-side band reading moves (module doc, stage 2): the roll
#: and pitch rotation, the inertia and the rate damping about x and y
ROTATION = ("inertia_error.xx", "inertia_error.yy", "rate_damping.x", "rate_damping.y")


def _rotation_steps(flights, params, rotor: bool, cand: Candidate, theta: np.ndarray, *,
                    shift: float, sigma: np.ndarray, side: TorqueSide,
                    views: _Views | None = None) -> np.ndarray:
    """``theta`` with the :data:`ROTATION` parameters refitted under ``side`` (module doc,
    stage 2): pooled Levenberg-Marquardt steps as :func:`_refine`'s (ridge in units of each
    parameter's typical size, at most :data:`REFINE_STEPS`, stopping below
    :data:`REFINE_TOL`), every other shared parameter and the rotor timing ``shift`` (s)
    held at their refined values; ``sigma`` the channels' noise scale (the refinement's).
    Why only these: the band determines the roll/pitch rotation where the rotors balance
    unmodelled moments; the rest keep what the whole band reads (moved with it, the yaw
    inertia, the timing and the motor lag shifted and a generated reference set no longer
    judged itself clean, tests/test_flapping_reading.py).

    How, cheaply: the weighted residual is affine in these four (on the torque side
    ``I_v w_dot + w x I_v w - M_model`` with ``I_v``'s diagonal scaled by ``1 + e`` and the
    model's damping ``-k w``; the yaw channel's ``(Iyy - Ixx) wx wy`` likewise), so one
    forward-difference Jacobian J at ``theta`` (exact for an affine map, up to round-off)
    gives every later step's cost ``|r + J d|^2`` and gradient ``Jᵀ(r + J d)``: the steps
    run on that quadratic (:func:`_rotation_lm` on :class:`_Quadratic`), a trial refused
    where the vehicle leaves the physical set (the triangle-inequality wall Izz <= Ixx + Iyy
    the references' yaw inertia sits near), as the evaluated steps refuse it. Kept where the
    residual at the end costs what the quadratic says to within :data:`REFINE_TOL` (-2 log L
    units, the steps' own stopping size); else the steps evaluated flight by flight."""
    free = [j for j, n in enumerate(cand.parameter_names) if n in ROTATION]
    if not free:
        return theta
    dt = float(getattr(flights[0], "fit", flights[0]).t[1]
               - getattr(flights[0], "fit", flights[0]).t[0])
    bounds = tuple(b[free] for b in fit_bounds(cand, params, dt))
    typical = typical_scales(cand, params)[free]
    probe = Reference(params, rotor, cand, theta.copy(), np.zeros_like(theta),
                      np.zeros_like(theta), sigma, np.ones_like(sigma),
                      np.zeros_like(sigma), 1.0, 1, {}, [], {}, side=side)
    views = _Views(flights) if views is None else views
    evaluated = _Evaluated(views, probe, free, shift)
    quad = _Quadratic(theta.copy(), free, *evaluated.pooled(theta), cand=cand, params=params)
    x = _rotation_lm(quad, theta, free, bounds=bounds, typical=typical)
    new = evaluated.cost(x)
    if np.isfinite(new) and abs(new - quad.cost(x)) < REFINE_TOL:
        return x
    return _rotation_lm(evaluated, theta, free, bounds=bounds, typical=typical)


@dataclass(frozen=True)
class _Evaluated:
    """The pooled cost of :func:`_rotation_steps`' columns ``free`` evaluated on the
    flights' ``views`` at rotor timing ``shift`` (s) with the ``probe`` reference (its
    residual on the torque side)."""

    views: _Views
    probe: Reference
    free: list
    shift: float

    def pooled(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """(JᵀJ, Jᵀr, |r|^2) summed over the flights at ``x`` (forward differences)."""
        self.probe.theta = x.copy()
        info, grad, cost = np.zeros((len(self.free),) * 2), np.zeros(len(self.free)), 0.0
        for i in range(len(self.views)):
            jac, r = jacobian(self.views.at(i, self.shift), self.probe, self.free,
                              self.probe.candidate.effects, with_base=True)
            info += jac.T @ jac
            grad += jac.T @ r
            cost += float(r @ r)
        return info, grad, cost

    def cost(self, x: np.ndarray) -> float:
        """|r|^2 summed over the flights at ``x``; inf outside the physical set."""
        return _cost(self.views, self.probe, x, self.shift)[0]


@dataclass(frozen=True)
class _Quadratic:
    """The pooled cost of :func:`_rotation_steps` where the residual is affine in the
    columns ``free``: from (``info`` JᵀJ, ``grad`` Jᵀr, ``base`` |r|^2) at ``theta``,
    ``|r + J d|^2`` and its gradient at ``theta + d`` (d nonzero on ``free`` only); inf
    where ``cand``'s vehicle on ``params`` leaves the physical set (ModelError)."""

    theta: np.ndarray
    free: list
    info: np.ndarray
    grad: np.ndarray
    base: float
    _: dataclasses.KW_ONLY
    cand: Candidate
    params: VehicleParams

    def pooled(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """(JᵀJ, Jᵀ(r + J d), |r + J d|^2) at ``x`` = ``theta + d``."""
        d = x[self.free] - self.theta[self.free]
        g = self.grad + self.info @ d
        return self.info, g, self.base + float(d @ (self.grad + g))

    def cost(self, x: np.ndarray) -> float:
        """``|r + J d|^2`` at ``x``, inf where its vehicle is not a physical one."""
        try:
            EffectSet(tuple(self.cand.effects(x))).apply_to_params(self.params)
        except ModelError:
            return float("inf")
        return self.pooled(x)[2]


def _damped_step(x: np.ndarray, info: np.ndarray, grad: np.ndarray, cost: float, *,
                 lam: float, typical: np.ndarray, bounds: tuple, cost_at):
    """One accepted Levenberg-Marquardt step of the calibration's pooled refinements
    (:func:`_refine`, :func:`_rotation_lm`) from ``x`` with information ``info`` (JᵀJ),
    gradient ``grad`` (Jᵀr) and ``cost`` there: the ridge ``lam`` in units of each
    parameter's ``typical`` size (a direction the data do not fix does not move),
    ``x - typical (info typical typical + lam I)^-1 typical grad`` clipped to ``bounds``
    (lower, upper); ``cost_at(trial)`` -> (cost, extra). A step that lowers the cost is
    taken and ``lam`` divided by 3 (not below 1e-3); else ``lam`` x4 and retried, up to
    1e6. Returns (trial, its cost, the new lam, extra), or None where no step lowers it."""
    lower, upper = bounds
    while lam < 1e6:
        info_z = info * np.outer(typical, typical) + lam * np.eye(len(x))
        trial = np.clip(x - typical * np.linalg.solve(info_z, typical * grad), lower, upper)
        new, extra = cost_at(trial)
        if new < cost:
            return trial, new, max(lam / 3.0, 1e-3), extra
        lam *= 4.0
    return None


def _rotation_lm(model, theta: np.ndarray, free: list, *, bounds: tuple,
                 typical: np.ndarray) -> np.ndarray:
    """``theta`` with the columns ``free`` refitted by pooled Levenberg-Marquardt steps as
    :func:`_refine`'s (ridge lambda in units of each parameter's ``typical`` size: 1 at
    the start, /3 after a step that lowers the cost, x4 and retried after one that does
    not; at most :data:`REFINE_STEPS`, stopping below :data:`REFINE_TOL`; clipped to
    ``bounds`` (lower, upper) of those columns) on ``model`` (:class:`_Evaluated` or
    :class:`_Quadratic`: ``pooled(x)`` -> (JᵀJ, Jᵀr, cost), ``cost(x)``, inf outside the
    physical set, a step there refused)."""
    x, lam = theta.copy(), 1.0
    for _ in range(REFINE_STEPS):
        info, grad, cost = model.pooled(x)

        def cost_at(sub, x=x):
            trial = x.copy()
            trial[free] = sub
            return model.cost(trial), trial

        step = _damped_step(x[free], info, grad, cost, lam=lam, typical=typical,
                            bounds=bounds, cost_at=cost_at)
        if step is None:
            break
        _, new, lam, x = step
        if cost - new < REFINE_TOL:
            break
    return x


#: what :func:`reference_key` hashes first: a new version when :class:`Calibrated` changes
CALIBRATED_SCHEMA = "quadsim.gap.calibrated/1"


@dataclass(frozen=True)
class Calibrated:
    """What the per-flight mode makes of the reference flights alone, kept between runs by
    the CLI's cache (:mod:`quadsim.gap.cache`, :func:`quadsim.gap.diagnose.diagnose_per_flight`):
    ``key`` (:func:`reference_key`), ``reference`` (the calibrated model with its
    self-check), ``vehicle`` (the set-fits-the-vehicle check on the references), ``notes``
    (their signal-delay notes) and ``count`` (how many references)."""

    key: str
    reference: Reference
    vehicle: object
    notes: tuple
    count: int


def code_version() -> str:
    """SHA-256 (hex) of the source of every module of the ``quadsim`` package (path and
    text, in path order) and the numpy and scipy versions: what a kept calibration is valid
    for (another commit, an edited module, another numpy: computed again)."""
    import hashlib

    import scipy

    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def reference_key(logs, params: VehicleParams, *, effects=None, window_s: float,
                  base: tuple = ()) -> str:
    """SHA-256 (hex) of everything the reference stage reads: :data:`CALIBRATED_SCHEMA`,
    :func:`code_version`, the parameter set, the explanations allowed (``effects``, None:
    all), the smoothing window (s), the effects already in the model (``base``, an effect
    file's: pickled) and every reference log, whole (its samples, its file name, its notes:
    pickled). The same key: the same :class:`Calibrated`, bit for bit."""
    import hashlib
    import pickle

    digest = hashlib.sha256(CALIBRATED_SCHEMA.encode())
    digest.update(code_version().encode())
    digest.update(pickle.dumps((params, None if effects is None else tuple(effects),
                                float(window_s), tuple(base)), protocol=4))
    for log in logs:
        digest.update(pickle.dumps(log, protocol=4))
    return digest.hexdigest()


def calibrate(flights, params: VehicleParams, *, base: tuple = (),
              torque_side: bool = True) -> Reference:
    """The reference model from prepared reference flights (:class:`quadsim.gap.diagnose.Flight`
    or their ``fit`` states); see the module doc. Raises InputError for fewer than two.
    ``base``: effects already in the model (``--effects-file``), carried as the shared
    candidate's ``base`` as held-out mode does (:func:`quadsim.gap.diagnose.nominal_reference`):
    applied first in every residual, never refitted; the shared groups are fitted on top.

    The thrust curve's slope (:func:`centred_curve`) is shared only where the references
    determine it: its spread below :data:`quadsim.gap.fitting.DETERMINED` times its prior's
    (:func:`curve_determined`, the rule a flight's own values are printed by). Why: an
    undetermined slope moves b with it flight by flight, and the envelope's trend of b
    then widens until a mass is "no difference". Decided in two steps: the shared
    parameters are first fitted without the slope, and the slope's spread is read there,
    linearised (:func:`_slope_spread`); only where that spread lies below the threshold is
    the model fitted again with the slope, and kept where its whole calibration still
    determines it (:func:`curve_determined`); else the calibration without the slope goes
    on from its fit. ``torque_side``: the roll and pitch residual taken on the torque side
    in the pooled fit and the between-flight scatter (:class:`TorqueSide`, module doc,
    stage 2); False: as the evidence takes it (the rule before; measurement)."""
    setup = _setup(flights, params, base)
    plain = Candidate(setup.cand.name, tuple(p for p in setup.cand.parts
                                             if p[0] != "thrust_curve"), setup.cand.base)
    fit = _bounded_fit(setup, plain)
    if CURVE_KEY in setup.cand.parameter_names and _slope_kept(
            *_slope_spread(setup, fit), setup.params):
        ref = _calibrated(setup, setup.cand, _bounded_fit(setup, setup.cand),
                          torque_side=torque_side)
        if ref is not None and curve_determined(ref):
            return ref
    return _calibrated(setup, plain, fit, torque_side=torque_side)


def curve_determined(ref: Reference) -> bool:
    """Whether the references determine their shared thrust-curve slope: identified, and
    its spread ``s_ref`` below :data:`quadsim.gap.fitting.DETERMINED` times its prior's
    (:func:`quadsim.gap.fitting.curve_slope_sd`)."""
    names = list(ref.candidate.parameter_names)
    if CURVE_KEY not in names:
        return True
    return _slope_kept(ref.s_ref[names.index(CURVE_KEY)], ref.identified.get(CURVE_KEY, True),
                       ref.params)


def _slope_kept(spread: float, identified: bool, params: VehicleParams) -> bool:
    return bool(identified and spread < DETERMINED * curve_slope_sd(params))


#: the shared thrust curve's slope (:func:`centred_curve`)
CURVE_KEY = "thrust_curve.linear"


@dataclass(frozen=True)
class _Setup:
    """What both calibrations of one reference set (thrust-curve slope shared or not) read,
    computed once (:func:`_setup`): ``views`` (the flights' :class:`_Views`), ``start`` (s,
    the starting rotor timing), ``states`` (the fit states read at it), ``rotor`` (every
    flight logs commands), ``params`` (with the references' command map), ``dt`` (s, the
    fit step), ``sigma0`` (C,) (the bounded fit's noise scale), ``vbat_ref`` (V or None),
    ``cand`` (the shared candidate with the slope, :func:`centred_curve`) and ``exponent``
    (the motors' load exponent, :func:`quadsim.gap.residual.load_exponent`, or None)."""

    flights: list
    views: _Views
    start: float
    states: list
    rotor: bool
    params: VehicleParams
    dt: float
    sigma0: np.ndarray
    vbat_ref: float | None
    cand: Candidate
    exponent: tuple | None


def _setup(flights, params: VehicleParams, base: tuple = ()) -> _Setup:
    """Stage 1 and the bounded fit's inputs (module doc) of the reference ``flights``: the
    rotor timing to start from (the references' mean cross-correlation delay), the command
    map (:func:`quadsim.gap.residual.fit_motor_map`), the noise scale of the bare model's
    residual, whether the battery law is tested (:data:`VBAT_TESTED`) and the shared
    candidate on top of ``base``. Raises InputError for fewer than two flights."""
    if len(flights) < 2:
        raise InputError("--reference: give at least 2 nominal flights")
    estimates = [f.delays_ms["rotor"] for f in flights
                 if (getattr(f, "delays_ms", None) or {}).get("rotor") is not None]
    start = float(np.clip(1e-3 * np.mean(estimates), -MAX_SHIFT_S, MAX_SHIFT_S)) \
        if estimates else 0.0
    views = _Views(flights)     # each flight's rotor spectra, for every timing read
    states = [views.at(i, start) for i in range(len(views))]
    rotor = all(s.command is not None for s in states)
    # the load exponent read on the window means the command map is fitted on (the same
    # states: their timing search done once, quadsim.gap.residual._window_means)
    exponent = load_exponent(states, params) if rotor else None
    if rotor:
        params = fit_motor_map(states, params)
    dt = float(states[0].t[1] - states[0].t[0])
    sigma0 = noise_scale(np.concatenate([residuals(s, params, list(base), rotor_channel=rotor)
                                         for s in states]), dt, floor=noise_floor(params, rotor))
    logged = rotor and all(s.vbat is not None and bool(np.all(np.isfinite(s.vbat)))
                           for s in states)
    vbat_ref, vbat_spread = voltage_spread(states) if logged else (None, 0.0)
    vbat = logged and vbat_spread >= VBAT_TESTED
    cand = dataclasses.replace(per_flight_candidate(rotor, vbat, pose=all(s.pose for s in states)),
                               base=tuple(base))
    return _Setup(list(flights), views, start, states, rotor, params, dt, sigma0, vbat_ref,
                  centred_curve(cand, states), exponent)


def _bounded_fit(setup: _Setup, cand: Candidate):
    """The bounded least-squares fit of ``cand`` on the references at the starting timing
    (module doc, stage 2; :func:`quadsim.gap.fitting.fit_candidate`, 40 evaluations)."""
    return fit_candidate(cand, setup.states, setup.params, setup.sigma0,
                         rotor_channel=setup.rotor, max_nfev=40, compact=True)


def _slope_spread(setup: _Setup, fit) -> tuple[float, bool]:
    """(spread, identified) of the shared thrust curve's slope read at ``fit``, the bounded
    fit without the slope (:func:`calibrate`): the model with the slope (``setup.cand``) at
    ``fit.theta`` and the slope and curvature at their "off" values (0: the same model),
    linearised there; each part as the whole calibration takes it.

    spread = sqrt(se^2 + tau^2) (N s/rad), the reference spread ``s_ref`` of
    :func:`curve_determined`. ``se``: the slope's pooled standard error as
    :func:`quadsim.gap.fitting.fit_candidate` states it, ``sqrt(s2 c (JᵀJ)^-1)`` of the
    residual over the bounded fit's noise scale ``setup.sigma0``, its mean square ``s2``
    (over its degrees of freedom) and correlation time ``c`` there, ``JᵀJ`` summed over
    the flights' forward-difference Jacobians (inverted in units of each parameter's
    typical size, :func:`_covariance`). ``tau``: the between-flight scatter of
    :func:`_scatter` (one Gauss-Newton step per flight) with the noise model and the
    discrepancy term of the residual at ``fit`` (stages 4-5), as :func:`_calibrated` reads
    it at the refined values. One set of Jacobians serves both: the noise model's weights
    are per channel, so the information in ``sigma0``'s units is each channel's
    information rescaled (:func:`_scatters`' ``pooled``). ``identified``: the slope moves
    the residual and 1.96 se lies inside half its plausible range (``fit_candidate``'s rule;
    never at a bound here). Why at the fit without the slope: the one-step values, and so
    the scatter, come from any point near the pooled one, and the slope's own standard
    error hardly moves with it; the fit with the slope then runs only where it is kept."""
    cand = setup.cand
    names = list(cand.parameter_names)
    plain = dict(zip(fit.candidate.parameter_names, fit.theta))
    lower, upper = fit_bounds(cand, setup.params, setup.dt)
    off = np.clip(start_off(cand), lower, upper)
    theta = np.array([plain.get(n, off[k]) for k, n in enumerate(names)], float)
    effects = cand.effects(theta)
    per_flight = [residuals(s, setup.params, effects, rotor_channel=setup.rotor)
                  for s in setup.states]
    discrepancy = fit_discrepancy(per_flight, setup.states, proportional_rotors(setup.params))
    sigma, tau, _ = _noise_model(setup.states, setup.params, setup.rotor, effects,
                                 discrepancy, per_flight=per_flight)
    probe = Reference(setup.params, setup.rotor, cand, theta, np.zeros_like(theta),
                      np.zeros_like(theta), sigma, tau, np.zeros_like(sigma), 1.0, 1, {}, [],
                      {})
    probe.discrepancy = discrepancy
    channels: list = []
    scatter = _scatters(setup.states, probe, [None], pooled=channels)[0]
    free = [j for j, n in enumerate(names) if n not in POOLED]
    # the information in sigma0's units: channel c's Jacobian is the raw one over
    # sigma_c sqrt(tau_c) (Reference.weights), the bounded fit's over sigma0_c
    info = np.einsum("c,cpq->pq", sigma ** 2 * tau / setup.sigma0 ** 2, channels[0])
    scaled = np.concatenate(per_flight) / setup.sigma0
    s2 = float(np.sum(scaled ** 2)) / max(1, scaled.size - len(fit.theta))
    cov = _covariance(info, typical_scales(cand, setup.params)[free]) * s2 \
        * correlation_time(scaled)
    j = names.index(CURVE_KEY)
    col = free.index(j)
    se = float(np.sqrt(max(cov[col, col], 0.0)))
    identified = bool(info[col, col] > 0 and 1.96 * se < 0.5 * (upper[j] - lower[j]))
    return float(np.hypot(se, scatter[j])), identified


def _calibrated(setup: _Setup, cand: Candidate, fit, *, torque_side: bool = True
                ) -> Reference | None:
    """The calibration (module doc, stages 2-7) of ``cand`` from its bounded fit ``fit`` on
    ``setup``'s references; None where ``cand`` shares the slope and the fit's own spread of
    it shows it undetermined (the between-flight scatter only widens it), before the
    refinement pays for it."""
    flights, views, params, rotor, dt = (setup.flights, setup.views, setup.params,
                                         setup.rotor, setup.dt)
    if CURVE_KEY in cand.parameter_names:
        j = cand.parameter_names.index(CURVE_KEY)
        if not _slope_kept(fit.stderr[j], bool(fit.identifiable[j]), params):
            return None
    theta, shift, shift_se, wind_se = _refine(flights, params, rotor, cand, fit.theta,
                                              shift=setup.start, sigma=setup.sigma0,
                                              views=views)
    # module doc, stage 2: where the whole band reads no plausible vehicle, the roll and
    # pitch rotation is read where the data fix it, kept where the band determines it
    side = torque_side_of(setup.states) if torque_side and rotation_implausible(
        cand, theta, params) else None
    if side is not None:
        turned = _rotation_steps(flights, params, rotor, cand, theta, shift=shift,
                                 sigma=setup.sigma0, side=side, views=views)
        if rotation_implausible(cand, turned, params) or np.any(band_explained(
                [views.at(i, shift) for i in range(len(views))], params, rotor,
                cand.effects(turned), side) < BAND_R2):
            side = None
        else:
            theta = turned
    stderr = fit.stderr.copy()
    for j, name in enumerate(cand.parameter_names):
        stderr[j] = wind_se.get(name, stderr[j])
    states = [views.at(i, shift) for i in range(len(views))]
    per_flight = [residuals(s, params, cand.effects(theta), rotor_channel=rotor)
                  for s in states]
    discrepancy = fit_discrepancy(per_flight, states, proportional_rotors(params))
    sigma, tau, log_ms = _noise_model(states, params, rotor, cand.effects(theta), discrepancy,
                                      per_flight=per_flight)
    mean = log_ms.mean(axis=0)
    spread, dof, pooled = moderated_spread(log_ms)
    ref = Reference(params, rotor, cand, theta, stderr,
                    np.zeros_like(fit.theta), sigma, tau, mean, spread, dof,
                    signal_delays(flights),
                    [getattr(f, "name", "") for f in flights],
                    dict(zip(cand.parameter_names, map(bool, fit.identifiable))),
                    shift, shift_se, vbat_ref=setup.vbat_ref,
                    at_bound=bounded(cand, params, theta, dt),
                    bounds=fit_bounds(cand, params, dt))
    ref.lof_pooled = pooled
    ref.discrepancy = discrepancy
    ref.log_ms = log_ms
    ref.load_exponent = setup.exponent
    _complete(ref, states, log_ms, side)
    return ref


def _complete(ref: Reference, states, log_ms: np.ndarray, side: TorqueSide | None = None
              ) -> None:
    """Fill in ``ref`` (pooled fit and noise model done) the fields computed from it on the
    aligned reference ``states`` (log mean squares ``log_ms`` (n, C)): the drags' quadratic
    equivalents, the timing flag, the between-flight scatter (stage 3) and the envelope
    (stage 7). ``side``: the roll and pitch residual's
    :class:`TorqueSide`, which the scatter's steps read as the pooled fit did (None: none)."""
    cand = ref.candidate
    ref.quadratic_drag = quadratic_equivalent(states, ref)
    ref.quadratic_drag_axes = quadratic_equivalent(states, ref, per_axis=True)
    ref.quadratic_vertical_axes = vertical_equivalent(states, ref)
    ref.timing = all(s.rotor_speed is not None for s in states)   # as _refine fits it
    own: list = []
    rot: list = []      # with a side: the rotation's own values as its pooled fit reads them
    scatters = _scatters(states, ref, [own, rot], side)
    ref.scatter = scatters[0]
    if side is not None:
        scatter = scatters[1]
        cols = [j for j, n in enumerate(cand.parameter_names) if n in ROTATION]
        ref.scatter[cols] = scatter[cols]
        own[0][:, cols], own[1][:, cols] = rot[0][:, cols], rot[1][:, cols]
    ref.per_flight = PerFlight(
        np.array([coordinates(s) for s in states]), own[0], own[1],
        np.array([ref.identified.get(k, True) for k in cand.parameter_names]),
        _noise_biased(cand.parameter_names, own[1] ** 2 * np.array([[len(s.t)] for s in states])),
        _excitations(states))
    ref.envelope = ref.per_flight.envelope(log_ms)


def _excitations(states) -> np.ndarray | None:
    """(n, C') the reference flights' :func:`quadsim.gap.reference.excitation`; None where
    they do not all give as many channels (some without rotor speeds)."""
    rows = [excitation(s) for s in states]
    return np.array(rows) if len({len(r) for r in rows}) == 1 else None


#: the band where the rotors drive the body (Hz): above ~3 Hz the aerodynamic moments (velocity
#: effects) are small against the torque; below 16 Hz common 18-20 Hz log filters pass > 0.9.
#: One source for both readers: :mod:`quadsim.identify.rotation` (a later stage) imports it
BAND_HZ = (4.0, 16.0)
#: the band fit's acceptance (R^2 of the band-passed moment explained), as the whole-band
#: inertia fit's (quadsim.identify.from_logs INERTIA_R2); imported by identify.rotation too
BAND_R2 = 0.5
#: the body axes (x roll, y pitch) whose moment residual the calibration reads on the torque
#: side in the band where the rotors drive the body (:class:`TorqueSide`; module doc, stage 2)
TORQUE_SIDE_AXES = (0, 1)


@dataclass(frozen=True)
class TorqueSide:
    """The calibration's roll and pitch residual where the data determine the inertia
    (module doc, stage 2): in newton-metres of the candidate's own inertia,
    ``M_meas - M_model`` = ``I_v w_dot + w x I_v w - M_model`` instead of
    :func:`quadsim.gap.fitting.residuals`' ``I (I_v^-1 (M_meas - M_model))``, band-passed to
    :data:`quadsim.gap.calibrate.BAND_HZ` (zero-phase 4th-order Butterworth, as
    :mod:`quadsim.identify.rotation`), on the body ``axes`` (0 x, 1 y); the other channels
    unchanged. ``rate_hz``: the fit samples' rate (Hz; :func:`torque_side_of` builds one
    only where it shows the band). A log of several airborne stretches is filtered across
    its joins as one series (their few edge samples are a small share of a flight).
    Called on the residual (N, C) with the nominal ``params`` and
    the candidate's ``effects``; returns (N, C). The chosen axes are the residual times
    ``I^-1 I_v`` restricted to them (the inertia's off-diagonal terms are the parameter
    set's, unchanged by ``inertia_error``)."""

    rate_hz: float
    axes: tuple = TORQUE_SIDE_AXES

    def __call__(self, r: np.ndarray, params: VehicleParams, effects: list) -> np.ndarray:
        vehicle = EffectSet(tuple(effects)).apply_to_params(params)
        back = np.linalg.solve(np.asarray(params.inertia, float),
                               np.asarray(vehicle.inertia, float))
        cols = [3 + a for a in self.axes]
        out = np.array(r, dtype=float, copy=True)
        out[:, cols] = self.band(r[:, 3:6] @ back[:, list(self.axes)])
        return out

    def band(self, x: np.ndarray) -> np.ndarray:
        """``x`` (N, k) band-passed to :data:`quadsim.gap.calibrate.BAND_HZ` (zero-phase
        4th-order Butterworth at ``rate_hz``)."""
        # scipy's sosfiltfilt bit for bit, its initial conditions kept per design
        return sosfiltfilt0(_band_sos(self.rate_hz), x)


@functools.lru_cache(maxsize=8)
def _band_sos(rate_hz: float) -> np.ndarray:
    """The second-order sections of :meth:`TorqueSide.band`'s filter at ``rate_hz`` (Hz):
    the same numbers each call, designed once per rate (the design cost as much as the
    filtering on a flight's few thousand samples)."""
    from scipy import signal

    sos = signal.butter(4, BAND_HZ, btype="bandpass", fs=rate_hz, output="sos")
    sos.setflags(write=False)
    return sos


def band_explained(states, params: VehicleParams, rotor: bool, effects: list,
                   side: TorqueSide) -> np.ndarray:
    """Per axis of ``side`` (roll, pitch) the share of the references' band-passed body
    moment ``I_v w_dot + w x I_v w`` (N m, the candidate's vehicle) that the model of
    ``effects`` explains there, pooled over ``states``: ``1 - sum r^2 / sum m^2`` with r the
    :class:`TorqueSide` residual and m that moment, both band-passed (the R^2 of
    :mod:`quadsim.identify.rotation`'s band fit, whose acceptance :data:`BAND_R2` the
    calibration applies: module doc, stage 2)."""
    vehicle = EffectSet(tuple(effects)).apply_to_params(params)
    cols = [3 + a for a in side.axes]
    num, den = np.zeros(len(cols)), np.zeros(len(cols))
    for st in states:
        r = side(residuals(st, params, effects, rotor_channel=rotor), params, effects)
        m = side.band(measured_wrench(st, vehicle)[1][:, list(side.axes)])
        num += np.sum(r[:, cols] ** 2, axis=0)
        den += np.sum(m ** 2, axis=0)
    return 1.0 - num / np.maximum(den, 1e-300)


def rotation_implausible(cand: Candidate, theta: np.ndarray, params: VehicleParams) -> bool:
    """Whether the pooled fit ``theta`` of ``cand`` reads a roll or pitch inertia error
    outside its plausible range (:func:`quadsim.gap.fitting.plausibility`: -50 .. +100 %,
    "a factor 2 is another vehicle"): the whole band then does not determine the vehicle's
    inertia (module doc, stage 2)."""
    names = list(cand.parameter_names)
    return any(not plausibility(key, float(theta[names.index(key)]), params)[1]
               for key in ROLL_PITCH_INERTIA if key in names)


#: the shared parameters :func:`rotation_implausible` reads
ROLL_PITCH_INERTIA = ("inertia_error.xx", "inertia_error.yy")


def torque_side_of(states) -> TorqueSide | None:
    """The :class:`TorqueSide` of fit ``states`` (their first two samples' step), or None
    where they are sampled below 2.5 times the band's upper edge (the band is not shown:
    the rule of :func:`quadsim.identify.rotation.band_parts`) or are too short for the
    filter's padding."""
    s = states[0]
    rate = 1.0 / float(s.t[1] - s.t[0])
    # sosfiltfilt's default padding: 3 (2 sections + 1) samples, 4 sections here
    if rate < 2.5 * BAND_HZ[1] or min(len(f.t) for f in states) <= 3 * (2 * 4 + 1):
        return None
    return TorqueSide(rate)


def _noise_model(states, params: VehicleParams, rotor: bool, effects: list,
                 discrepancy=None, *, per_flight: list | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Module doc, stages 4-5: (sigma (C,), tau (C,), log_ms (n, C)) of the calibrated
    model's residual (``effects``) over the n aligned reference ``states``, after the
    references' systematic residual (``discrepancy``'s centre,
    :func:`quadsim.gap.reference.centre_term`; None: none): per-channel RMS
    over all of them, floored at :func:`quadsim.gap.fitting.noise_floor` (N, N m, rad/s);
    per-channel integrated correlation time, the mean over the flights (samples); each
    flight's log mean square over sigma_c^2. ``per_flight``: those residuals (N_j, C) where
    already computed (unchanged here)."""
    if per_flight is None:
        per_flight = [residuals(s, params, effects, rotor_channel=rotor) for s in states]
    per_flight = [r - centre_term(s, discrepancy, r.shape[1])
                  for r, s in zip(per_flight, states)]
    pooled = np.concatenate(per_flight)
    sigma = np.maximum(np.sqrt(np.mean(pooled ** 2, axis=0)), noise_floor(params, rotor))
    tau = np.array([np.mean([correlation_time(r[:, [c]] / sigma[c]) for r in per_flight])
                    for c in range(pooled.shape[1])])
    log_ms = np.log([np.mean(r ** 2, axis=0) / sigma ** 2 for r in per_flight])
    return sigma, tau, log_ms


def signal_delays(flights) -> dict:
    """Module doc, stage 6: signal name -> (mean, sample standard deviation (0 for one),
    count) of the flights' ``delays_ms`` (ms) over those that estimated it."""
    delays = {}
    for key in {k for f in flights for k in getattr(f, "delays_ms", {})}:
        v = [f.delays_ms[key] for f in flights if getattr(f, "delays_ms", {}).get(key) is not None]
        if v:
            delays[key] = (float(np.mean(v)), float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
                           len(v))
    return delays


#: shared groups whose least-squares value is biased by noise in what it scales, in
#: proportion to the inverse information (:func:`inverse_information`): the rotor thrust and
#: drag torque factors, the inertia and the rotors' gyroscopic inertia scale forces and
#: torques made from the logged rotor speeds (telemetry noise on the regressor: errors in
#: variables), and the motor lag is fitted in closed loop (the command answers the noise the
#: controller sees). The others scale quantities measured with little noise (the velocity
#: for drags and winds, the gyro's rate for damping), and their drift with how a flight is
#: flown is a form error that grows with the motion (a quadratic rate drag read as
#: linear damping), the place's line.
NOISE_BIASED = ("nominal_refit", "inertia_error", "gyroscopic", "motor_lag")


def _noise_biased(names, info: np.ndarray) -> np.ndarray:
    """``info`` with NaN in the columns of groups not in :data:`NOISE_BIASED` (no
    inverse-information line for them)."""
    keep = np.array([n.split(".")[0] in NOISE_BIASED for n in names])
    return np.where(keep, info, np.nan)


def inverse_information(states, reference: Reference) -> np.ndarray:
    """Inverse information per sample (P,) of each shared parameter on one flight's aligned
    ``states``: the squared standard error of its one-step estimate alone (:func:`_scatter`)
    times its samples. How little of each parameter a flight's motion shows per sample, the
    place of :mod:`.reference`'s inverse-information trend: least squares biases a value by
    the noise of its regressor over that regressor's signal (errors in variables), and the
    signal is what the information counts."""
    own: list = []
    _scatter([states], reference, own)
    return own[1][0] ** 2 * len(states.t)


def quadratic_equivalent(states, reference: Reference, per_axis: bool = False) -> float:
    """C_d A (m^2) of a quadratic airframe drag ``-1/2 rho C_d A |v| v`` (horizontal, body x
    and y: :mod:`quadsim.effects.body_drag`; ``per_axis``: each body axis on its own air
    speed, ``-1/2 rho C_d A |v_i| v_i``) in place of the references' shared rotor drag
    (linear in air speed): fitted to their own flights' horizontal air force by least squares
    on the body-frame force (N), every other shared value held (:func:`_drag_refit`). What the
    references' drag is if its law is quadratic: an airframe's drag is, a rotor's in-plane
    drag is linear, and flights at the references' speeds cannot
    tell the two apart, a wind of several m/s can
    (:func:`quadsim.gap.explanations.wind_readings`). 0 where the reference model has no
    rotor drag, or where the area lies beyond body drag's plausible range (:func:`_drag_refit`:
    flights too slow for a quadratic law to carry their drag with an airframe's area)."""
    from ..effects import make_effect

    if reference.values().get("rotor_drag.coefficient", 0.0) <= 0.0:
        return 0.0
    return _drag_refit(states, reference, "rotor_drag",
                       make_effect("body_drag", cd_area=1.0, per_axis=float(per_axis)),
                       slice(0, 2), scaled="cd_area")


def vertical_equivalent(states, reference: Reference) -> float:
    """C_d A (m^2) along body z of a drag per body axis, ``-1/2 rho C_d A |v_z| v_z``, in
    place of the references' shared vertical body drag (on the air speed, ``-1/2 rho C_d A
    |v| v_z``): fitted to their own flights' body-z air force (:func:`_drag_refit`). The
    vertical drag under the law a flight may show (:mod:`.evidence`).

    Why: a per-axis law that replaced only the references' horizontal (rotor) drag and kept
    their vertical one on the air speed reads the law's own vertical form as the flight's.
    0 where the references share no vertical drag, or where the area lies beyond body drag's
    plausible range (:func:`_drag_refit`: the law then keeps their vertical drag as it is)."""
    from ..effects import make_effect

    if reference.values().get("body_drag.cd_area_vertical", 0.0) <= 0.0:
        return 0.0
    return _drag_refit(states, reference, "body_drag",
                       make_effect("body_drag", cd_area=0.0, cd_area_vertical=1.0,
                                   per_axis=1.0), slice(2, 3), scaled="cd_area_vertical")


def _drag_refit(states, reference: Reference, group: str, unit, axes: slice, *,
                scaled: str) -> float:
    """Least-squares factor (>= 0) on the ``unit`` drag effect (its parameter ``scaled`` at
    1) that fits the references' body-frame force on ``axes`` (N) left to their shared
    ``group`` drag: the measured force less the reference model without that group, over
    their own flights.

    The measured force and not the group's own: fitted to the model's linear force (the
    group's projection onto its own law), the quadratic area comes out low by the squared
    cosine between the two laws' force histories over the references (a projection of a
    projection).

    0 where the factor lies beyond the plausible range of the ``unit`` effect's parameters
    (body drag's C_d A: at most 1 m^2, :mod:`quadsim.effects.body_drag`). A quadratic force
    grows with the air speed squared: on references flown slowly (hovering, held in place)
    a drag that is linear in air speed takes an area of square metres to carry as one (a
    Crazyflie held at 0.1 m/s: 2 m^2 along z). Such an area is no airframe's, no law the
    references can be read under; as a fixed value of every reading under that law it would
    also be refused as an effect, and with it every flight."""
    from .residual import measured_wrench, model_wrench

    shared, n_base = reference.effects(), len(reference.candidate.base)
    # effects already in the model (an effect file) stay, as in quadsim.gap.evidence
    without = shared[:n_base] + [e for e in shared[n_base:] if e.name != group]
    num = den = 0.0
    for s in states:
        base = model_wrench(s, reference.params, without)[0][:, axes]
        target = measured_wrench(s, reference.params)[0][:, axes] - base
        unit_force = model_wrench(s, reference.params, without + [unit])[0][:, axes] - base
        num += float(np.sum(target * unit_force))
        den += float(np.sum(unit_force * unit_force))
    factor = max(0.0, num / den) if den > 0 else 0.0
    upper = next(p.upper for p in type(unit).parameters if p.name == scaled)
    return factor if factor <= upper else 0.0
