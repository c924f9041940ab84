"""The calibrated reference model as a data type, and the weighted residual every per-flight
comparison is made of (:mod:`quadsim.gap.calibrate` fits it; :mod:`quadsim.gap.evidence`
weighs a flight against it).

A :class:`Reference` holds the nominal parameter set with the data's motor map, the shared
parameters' values theta_ref with their pooled standard error and between-flight scatter,
the per-channel noise scale sigma_c (N, N m, rad/s) and correlation time tau_c (samples), the
lack-of-fit statistics, the references' signal delays and their rotor-speed timing. The
weighted residual (:func:`weighted_residual`) divides each channel by
``sigma_c sqrt(tau_c)``, so that its squared sum is -2 log L. A flight's rotor speeds are
read at the references' timing (:func:`aligned`: shifted band-limited on the fit samples).

Example::

    >>> r = weighted_residual(reference.align(flight), reference, reference.effects())
    >>> float(np.sum(r ** 2))          # -2 log L of "no difference", up to a constant
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.errors import ModelError
from ..vehicle.params import VehicleParams
from .discrepancy import centre_term
from .fitting import Candidate, parameter_bounds, residuals, typical_scales

__all__ = [
    "FD_STEP",
    "LackOfFitBaseline",
    "Reference",
    "aligned",
    "jacobian",
    "read_later",
    "rotor_spectra",
    "shifted",
    "weighted_residual",
]


#: finite-difference step of the Jacobians, in units of each parameter's typical size
#: (:func:`quadsim.gap.fitting.typical_scales`): the same relative step the fits use (diff_step).
FD_STEP = 1e-3


def shifted(states, delay_s: float, spectra: tuple | None = None):
    """``states`` with the rotor speeds (and their derivative) read ``delay_s`` later: the
    speeds a log that records them ``delay_s`` late had at each time.

    On a uniform time base the read is band-limited (:func:`read_later`): a Fourier phase
    shift, which passes every frequency with its full amplitude (``spectra``: the flight's
    :func:`rotor_spectra`, when it is read at many delays). Why not linear interpolation:
    between two samples it averages them, and the average of two noisy samples has up to
    half their noise power, so the timing likelihood would be a sawtooth with the fit
    sample's period. A non-uniform time base is read by linear interpolation."""
    if delay_s == 0.0 or states.rotor_speed is None:
        return states
    import dataclasses

    speed, accel = spectra if spectra is not None else rotor_spectra(states)
    if speed is not None and accel is not None:     # both in one inverse transform
        both = read_later(states.t, None, delay_s, np.hstack([speed, accel]))
        k = speed.shape[1]
        return dataclasses.replace(states, rotor_speed=np.ascontiguousarray(both[:, :k]),
                                   rotor_accel=np.ascontiguousarray(both[:, k:]))
    return dataclasses.replace(
        states, rotor_speed=read_later(states.t, states.rotor_speed, delay_s, speed),
        rotor_accel=None if states.rotor_accel is None
        else read_later(states.t, states.rotor_accel, delay_s, accel))


def rotor_spectra(states) -> tuple:
    """The mirrored spectra :func:`read_later` shifts, of the rotor speeds and their
    derivative (None each on a non-uniform time base or where the signal is missing): one
    flight's, computed once and passed to every :func:`shifted` of it."""
    return (_spectrum(states.t, states.rotor_speed),
            None if states.rotor_accel is None else _spectrum(states.t, states.rotor_accel))


def _spectrum(t: np.ndarray, x) -> np.ndarray | None:
    if x is None or not _uniform(t):
        return None
    x = np.asarray(x, dtype=float)
    return np.fft.rfft(np.concatenate([x, x[::-1]]), axis=0)


def _uniform(t: np.ndarray) -> bool:
    n = len(t)
    if n < 4:
        return False
    dt = (t[-1] - t[0]) / (n - 1)
    return bool(np.max(np.abs(np.diff(t) - dt)) <= 1e-6 * dt)


def read_later(t: np.ndarray, x: np.ndarray, delay_s: float,
               spectrum: np.ndarray | None = None) -> np.ndarray:
    """Samples ``x`` (N, K) on times ``t`` (N,) read ``delay_s`` later: x(t + delay_s)
    (:func:`shifted`). Uniform ``t`` (spacing within 1e-6 of its mean): the phase
    ``exp(2 pi i nu s)`` (s = delay_s / dt samples, nu in cycles per sample) on the spectrum
    of the series followed by its mirror image (``spectrum``: that spectrum, computed once
    per flight, :func:`rotor_spectra`). Mirrored, the periodic series has no jump at
    either end, so the spectrum does not ring there, and beyond the log's ends the read
    meets the mirror image (x(t_end + d) = x(t_end - d)). The read is smooth in ``delay_s``
    across whole samples: a delay fit's finite differences see the slope, not an edge. A
    non-uniform time base is read by linear interpolation. The columns are transformed
    one by one (numpy's FFT): the spectra of several series side by side read as each alone."""
    n = len(t)
    if spectrum is None:
        if not _uniform(t):
            x = np.asarray(x, dtype=float)
            return np.stack([np.interp(t + delay_s, t, c) for c in x.T], -1)
        spectrum = _spectrum(t, x)
    dt = (t[-1] - t[0]) / (n - 1)
    nu = np.fft.rfftfreq(2 * n)[:, None]        # cycles per sample
    return np.fft.irfft(spectrum * np.exp(2j * np.pi * nu * (delay_s / dt)), 2 * n,
                        axis=0)[:n]


def aligned(flight, delay_s: float):
    """The fit view of a prepared flight (:class:`quadsim.gap.diagnose.Flight`, or its fit
    states) with its rotor speeds read ``delay_s`` later (:func:`shifted`, band-limited on
    the fit samples). Why not shifted at the full log rate and decimated again: picking
    every k-th sample aliases what lies above the fit rate's Nyquist frequency, with a phase
    that moves with the shift. A shift of the fit samples moves what they hold, with its
    power, whatever the shift."""
    fit = getattr(flight, "fit", flight)
    if delay_s == 0.0 or fit.rotor_speed is None:
        return fit
    return shifted(fit, delay_s)


@dataclass(frozen=True)
class LackOfFitBaseline:
    """What a judged flight's per-channel residual is compared with in the lack-of-fit test
    when that level comes from flights other than the references of :class:`Reference`'s
    noise model: in held-out mode, the remainder a reading leaves on the *training* flights.

    ``mean_square`` (C,): per channel c, the mean over the training flights (or their halves,
    with one training flight) of their mean squared remainder over sigma_c^2
    (dimensionless; 1 = the noise model's level); ``log_spread``: the spread of
    log(ms_jc / sigma_c^2) about its per-channel mean, pooled over the channels
    (``dof`` = C (n - 1) degrees of freedom for n pieces); ``flights``: the names of the
    flights it was computed on; ``source``: what produced it, in words (e.g. "held-out:
    training flights' remainder after no_difference").

    Filled by the held-out judgment; :mod:`quadsim.gap.calibrate` leaves it None (the
    per-flight baseline is ``Reference.lof_mean``/``lof_sd``/``lof_dof``)."""

    mean_square: np.ndarray
    log_spread: float
    dof: int
    flights: tuple = ()
    source: str = ""


@dataclass
class Reference:
    """The calibrated model of what the reference flights share, with its uncertainty and
    its noise model: the one input of the judgment of a flight in both modes (per flight:
    :func:`quadsim.gap.calibrate.calibrate`; held out: :func:`quadsim.gap.heldout.
    nominal_reference`, the parameter set with a noise model of the training flights).

    Shapes: M shared parameters (``candidate.parameter_names``, each ``"effect.parameter"``),
    C residual channels (Fx Fy Fz in N, Mx My Mz in N m, then with ``rotor`` one rotor-speed
    channel per rotor in rad/s).

    - ``params``: the nominal :class:`~quadsim.vehicle.params.VehicleParams` with the
      references' static command -> speed map (:func:`quadsim.gap.motor_map.fit_motor_map`)
      where commands are logged.
    - ``rotor``: whether the rotor-speed channels are part of the residual (commands logged
      on every reference flight; :mod:`quadsim.gap.rotor_channel`).
    - ``candidate``: the shared parameters as one :class:`~quadsim.gap.fitting.Candidate`;
      ``theta`` (M,): their values theta_ref, each in its effect parameter's unit.
    - ``se_pool`` (M,): standard error of theta_ref from the pooled fit; ``scatter`` (M,):
      between-flight spread (random-effect tau); ``s_ref`` (M,) = sqrt(se_pool^2 +
      scatter^2): what a new nominal flight may show, the spread each explanation
      marginalises the shared parameters with (same units as ``theta``).
    - ``sigma`` (C,): per-channel residual RMS of the reference model on the references (N,
      N m, rad/s); ``tau`` (C,): per-channel integrated correlation time (samples at the fit
      rate); ``weights`` (C,) = 1 / (sigma_c^2 tau_c): the weight of a squared residual, so
      that the weighted residual's squared sum is -2 log L (:func:`weighted_residual`).
    - ``lof_mean`` (C,): mean over the references of log(ms_jc / sigma_c^2) (natural log of
      each flight's mean square over sigma_c^2); ``lof_sd``: its spread (float, or (C,) per
      channel, :mod:`quadsim.gap.moderated`); ``lof_dof``: its degrees of freedom;
      ``lof_pooled``: (spread, dof) pooled over the channels, or None.
    - ``baseline``: a :class:`LackOfFitBaseline` from flights other than the references
      (held-out mode), or None: the lack-of-fit baseline is then ``lof_*``.
    - ``delays_ms``: signal name (``"gyro"``, ``"rotor"``, ``"accel"``) -> (mean, sample
      standard deviation, count) over the references of that signal's delay against motion
      capture (ms, positive: the signal lags; :mod:`quadsim.logs.delays`).
    - ``names``: the reference flights' names; ``identified``: shared parameter -> whether the
      pooled fit identified it.
    - ``rotor_shift_s``, ``rotor_shift_se``: the references' rotor-speed timing offset d
      (s: the speeds are read d later, :meth:`align`) and its standard error (s).

    The remaining fields are documented where they are declared. :func:`quadsim.gap.calibrate.
    calibrate` fills the fields after ``identified`` once the pooled fit is done."""

    params: VehicleParams
    rotor: bool
    candidate: Candidate
    theta: np.ndarray
    se_pool: np.ndarray
    scatter: np.ndarray
    sigma: np.ndarray
    tau: np.ndarray
    lof_mean: np.ndarray
    #: float, or (C,) per channel at a flight beyond the references (.envelope)
    lof_sd: float | np.ndarray
    lof_dof: int
    delays_ms: dict
    names: list
    identified: dict
    rotor_shift_s: float = 0.0
    rotor_shift_se: float = 0.0
    #: the references' envelope and the model's trend along it (:mod:`.envelope`)
    envelope: object = None
    #: the references' mean battery voltage (V; None without a voltage log): the voltage at
    #: which their speed per command holds (:func:`voltage_spread`)
    vbat_ref: float | None = None
    #: shared parameter -> "lower" or "upper" where the references' pooled fit stopped at
    #: that bound (:func:`bounded`): their data say only that the value lies at or beyond it
    at_bound: dict = field(default_factory=dict)
    #: (lower, upper) bounds of the shared parameters in the references' fit
    #: (:func:`fit_bounds`): the reference model at a flight's place stays within them
    #: (:func:`quadsim.gap.envelope.local_reference`); None: the effects' plausible ranges
    bounds: tuple | None = None
    #: C_d A (m^2) of the quadratic airframe drag that gives the references' own horizontal
    #: air force (:func:`quadsim.gap.calibrate.quadratic_equivalent`); 0 where their model has
    #: none (no rotor drag, or it is not shared)
    quadratic_drag: float = 0.0
    #: the same with each body axis's drag on its own air speed (``per_axis``): the wind
    #: reading's third variant (:func:`quadsim.gap.explanations.wind_readings`)
    quadratic_drag_axes: float = 0.0
    #: C_d A (m^2) along body z under the law per body axis that gives the references' own
    #: vertical air force of their shared body drag (on the air speed, ``|v| v_z``):
    #: :func:`quadsim.gap.calibrate.vertical_equivalent`; the per-axis law carries it in place
    #: of that shared drag (:func:`quadsim.gap.explanations.quadratic_laws`); 0 where the
    #: references share none
    quadratic_vertical_axes: float = 0.0
    #: whether the references' rotor-speed timing was fitted (:func:`quadsim.gap.calibrate.
    #: calibrate`, wherever they log rotor speeds): a flight's own delay is read against it
    #: (the held-out mode's parameter-set reference has none)
    timing: bool = False
    #: (alpha, spread) of the speed-per-command exponent the references' own command ->
    #: speed map implies for a propeller change (:func:`quadsim.gap.motor_map.load_exponent`);
    #: None where their commands do not span enough to say
    load_exponent: tuple | None = None
    #: (spread, degrees of freedom) of the lack of fit pooled over the channels: what a
    #: flight outside the references' envelope is tested with at least
    #: (:mod:`quadsim.gap.moderated`); None: ``lof_sd`` is the pooled spread already
    lof_pooled: tuple | None = None
    #: the lack-of-fit baseline from flights other than the references (held-out mode's
    #: training flights, :class:`LackOfFitBaseline`); None: ``lof_mean``/``lof_sd``/``lof_dof``
    baseline: LackOfFitBaseline | None = None
    #: the references' systematic residual on flight-state features, with its between-flight
    #: covariance (:class:`quadsim.gap.discrepancy.Discrepancy`): taken off every residual
    #: (:func:`weighted_residual`) and marginalised with every explanation
    #: (:class:`quadsim.gap.problem.Problem`); None: none (fewer than 3 references, or a
    #: parameter-set reference)
    discrepancy: object = None
    #: (n, C) each reference flight's log(ms_jc / sigma_c^2) (the lack-of-fit baseline's
    #: data, ``lof_mean`` their mean): what the self-check leaves one flight out of
    #: (:mod:`quadsim.gap.selfcheck`); None where not kept
    log_ms: np.ndarray | None = None
    #: the self-check of the references against each other
    #: (:class:`quadsim.gap.selfcheck.SelfCheck`): what a reading's size is compared with
    #: (practical significance); None before it ran or without one
    self_check: object = None
    #: each reference flight's own fit (:class:`quadsim.gap.selfcheck.PerFlight`): what the
    #: between-flight scatter and the envelope are built from, kept for the self-check;
    #: None where not kept
    per_flight: object = None

    def align(self, flight):
        """A prepared flight's fit states with the references' rotor-speed timing
        (:func:`aligned` by ``rotor_shift_s``): what the reference model compares with."""
        return aligned(flight, self.rotor_shift_s)

    @property
    def s_ref(self) -> np.ndarray:
        """(M,) sqrt(se_pool^2 + scatter^2): the shared parameters' reference uncertainty."""
        return np.sqrt(self.se_pool ** 2 + self.scatter ** 2)

    @property
    def weights(self) -> np.ndarray:
        """Per-channel weight of a squared residual: 1 / (sigma_c^2 tau_c)."""
        return 1.0 / (self.sigma ** 2 * self.tau)

    def values(self) -> dict:
        """Shared parameter name -> theta_ref (float, its unit)."""
        return dict(zip(self.candidate.parameter_names, map(float, self.theta)))

    def effects(self, theta: np.ndarray | None = None) -> list:
        """The reference model's effects at ``theta`` (M,; default theta_ref)."""
        return self.candidate.effects(self.theta if theta is None else theta)


def weighted_residual(states, reference: Reference, effects: list,
                      memo: dict | None = None) -> np.ndarray:
    """Residual (N, C) of ``effects`` on ``states``, each channel times
    ``1 / (sigma_c sqrt(tau_c))``: its squared sum is the log-likelihood's -2x (module doc).
    ``memo``: residual parts kept across evaluations on the same ``states``
    (:func:`quadsim.gap.fitting.residuals`). With a discrepancy term
    (``reference.discrepancy``), its centre is taken off first
    (:func:`quadsim.gap.discrepancy.centre_term`)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor, memo=memo)
    r = r - centre_term(states, reference.discrepancy, r.shape[1], memo)
    return r * np.sqrt(reference.weights)


def jacobian(states, reference: Reference, columns: list[int], build, *,
             memo: dict | None = None, with_base: bool = False):
    """Forward-difference Jacobian (N C, len(columns)) of the weighted residual with respect
    to the shared parameters ``columns`` at theta_ref (``build(theta)`` -> effects);
    ``with_base``: (Jacobian, the weighted residual at theta_ref, flattened). The columns
    share the residual parts one parameter does not move (the rotations, the measured
    wrench of one vehicle, the rotor channel of one command -> speed model) through
    ``memo`` (a new one per call by default)."""
    memo = {} if memo is None else memo
    typical = typical_scales(reference.candidate, reference.params)
    _, upper = parameter_bounds(reference.candidate, reference.params)
    base = weighted_residual(states, reference, build(reference.theta), memo).ravel()
    out = np.empty((base.size, len(columns)))
    for j, k in enumerate(columns):
        h = FD_STEP * typical[k]
        if reference.theta[k] + h > upper[k]:      # a value at its upper bound: step down
            h = -h
        try:
            moved = _probe(states, reference, build, memo, k, h)
        except ModelError:      # the step crosses a wall of the physical set: the other way
            h = -h
            moved = _probe(states, reference, build, memo, k, h)
        out[:, j] = (moved - base) / h
    return (out, base) if with_base else out


def _probe(states, reference: Reference, build, memo, k: int, h: float) -> np.ndarray:
    """The weighted residual (flattened, (N C,)) with shared parameter ``k`` moved by ``h``
    (its unit). Raises ModelError where that leaves the physical set (e.g. an inertia
    breaking the triangle inequality Izz <= Ixx + Iyy): :func:`jacobian` then steps the
    other way."""
    theta = reference.theta.copy()
    theta[k] += h
    return weighted_residual(states, reference, build(theta), memo).ravel()
