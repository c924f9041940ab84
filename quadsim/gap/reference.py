"""The calibrated reference model as data: the model and its weighted residual, what the
reference flights share and the library lacks (the discrepancy term), the per-channel spreads
of their lack of fit, and the envelope they were flown in (the model at a flight flown
elsewhere in it or outside it).

Moderated lack-of-fit spreads
-----------------------------

Per-channel spreads of the references' lack of fit, moderated towards their common one.

The lack-of-fit test (:func:`quadsim.gap.judge.lack_of_fit`) compares a flight's log mean
square per channel with the references'. Their scatter differs by channel (several-fold
between the quiet and the noisy channels). One spread pooled over the channels then
over-tests the noisy channels and under-tests the quiet ones; a spread per channel alone
rests on n - 1 degrees of freedom (7 for 8 references). The moderated spread (Smyth 2004,
"Linear models and empirical Bayes methods for assessing differential expression", SAGMB 3:
the limma method) is in between, by the channels' own evidence:

the per-channel variances s_c^2 (d = n - 1 degrees of freedom each) are taken as draws from
a scaled inverse chi-square prior (nu0 degrees of freedom about s0^2). With
``e_c = log s_c^2 - digamma(d/2) + log(d/2)``, the prior's size follows from the scatter
of e over the channels: ``trigamma(nu0 / 2) = var(e) - trigamma(d/2)`` (no prior scatter
left: nu0 infinite, every channel at the pooled spread), and
``log s0^2 = mean(e) + digamma(nu0/2) - log(nu0/2)``. Each channel's moderated variance is
``(nu0 s0^2 + d s_c^2) / (nu0 + d)`` with ``nu0 + d`` degrees of freedom, never more than
the pooled test's C d.

A channel's spread is what the references show *within* their envelope; how a quiet
channel grows beyond them they do not show, so a flight outside the envelope is tested
with the larger of the moderated and the pooled spread
(:func:`quadsim.gap.reference.local_reference`).

Example::

    >>> spread, dof, pooled = moderated_spread(log_ms)    # log_ms (n flights, C channels)

The discrepancy term
--------------------

What the reference flights share and the library lacks: the discrepancy term.

The calibrated reference model (:mod:`quadsim.gap.calibrate`) leaves a residual on the
reference flights that is not all noise: where the vehicle does something no library effect
describes (a real Crazyflie's rotor-flapping moments, a quadratic drag under a linear law),
the residual follows the flight state, flight after flight. A flight flown harder than its
references then shows more of it, and any explanation that soaks part of it up on that
flight wins -- a confident name for what every reference shares.

The term describes that systematic residual on a few physical features of the flight state,
per residual channel c (SI units; v_b the velocity in body axes, m/s; omega the body rate,
rad/s; omega_dot its derivative, rad/s^2)::

    r_c(t) = phi_c(t)ᵀ beta_c + noise,      beta_c ~ N(beta_bar_c, Sigma_c)

- force channel F_i (N, i = x, y, z): phi = (|v_b| v_b,i, omega_dot): a quadratic drag on
  that axis (the law a linear drag model lacks), and the accelerometer's offset r from the
  centre of mass, whose specific force carries omega_dot x r (4 features). Not v_b,i as
  well: at the references' near-constant speeds v and |v| v move together, and their
  difference extrapolates wildly to a flight flown faster (benchmarks/HISTORY.md);
- moment channels Mx, My, Mz (N m): phi = (v_b, omega, omega_dot): moments of the air speed
  (rotor flapping, the rotors' drag moment), of the body rate (damping) and of the angular
  acceleration (inertia), on any axis (9 features);
- rotor-speed channels rotor_k (rad/s), where the reference model's map for that rotor is
  a gain through the origin (:func:`quadsim.gap.residual.proportional_rotors`; none
  elsewhere): phi = u_k - u_bar_k, rotor k's command averaged over
  :data:`quadsim.gap.residual.MAP_WINDOW_S` (a moving mean: the command's level, not its
  manoeuvres) less the references' mean of it (1 feature, in the log's command unit).
  Why: the reference model's static command -> speed map
  (:func:`quadsim.gap.residual.fit_motor_map`) is a gain through the origin where the
  references' commands span too narrow a range for a line (a gentle path): its slope at
  their level is then an assumption (an ideal motor), and a flight flown at another level
  (heavier, a rotor loaded harder) meets the slope's error,
  ``(k_true - k_map) (u - u_bar)``, on its rotor channels. Where the map is a line the
  references determine its slope, and the rotor channels keep no term: the rotor channel's
  own timing error on flights flown harder than the references then outweighs what the term
  removes (measured: CHANGELOG.md, "A rotor's command level"). Where the references fly at
  one level the slope is not determined, and the term's spread lets a flight's level error
  go as what they cannot tell.

No constant and no acceleration feature on the force channels: a mass or thrust change is a
steady force and one proportional to the acceleration, and it must stay the flight's own.
No constant on the rotor channels either: at the references' level the map is theirs, and
a speed off it there (a battery's sag, a propeller's load) is the flight's own.

``beta_bar_c`` is the mean of each reference flight's least-squares coefficients and
``Sigma_c`` their between-flight covariance times (1 + 1/n) (what a new flight of the same
vehicle may show, n references; on a rotor channel the random effect instead, the scatter
beyond each estimate's own noise plus the mean's uncertainty, :func:`_from_coefs`), with a
ridge of :data:`RIDGE` times its diagonal (a covariance of n flights has rank n - 1 at
most). Every explanation's residual is taken after ``phi beta_bar`` (:func:`centre_term`)
and the flight's own ``beta_c - beta_bar_c`` is marginalised with ``Sigma_c`` as extra
linear columns of the shared parameters' marginal (:func:`columns`;
:class:`quadsim.gap.evidence.Marginal`): an explanation earns evidence only for what this
flight shows beyond what its references already show.

Example::

    >>> d = fit_discrepancy(states_list, params, rotor, effects)
    >>> r = residuals(states, params, effects, rotor_channel=rotor) - centre_term(states, d)

The reference model
-------------------

The calibrated reference model as a data type, and the weighted residual every per-flight
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

The envelope
------------

The reference flights' envelope, and the reference model at a flight flown elsewhere in it
or outside it.

The reference model (:mod:`.calibrate`) is fitted on flights of one envelope, and what its
shared values absorb of the physics it lacks depends on how the flights were flown. A
flight flown elsewhere meets the model's *extrapolation error*; read against the
references' own residual statistics it looks like an effect. Two parts of it are physics
the reference model now shares (:func:`.calibrate.per_flight_candidate`: the motor map's
gain and the vertical drag, both drifting with the flight's envelope); the rest is measured
here, over the references themselves, and widens the
reference model for a flight beyond them. Every judged flight's answer states whether it
lies outside its references' envelope, along which coordinate and by how much.

Coordinates (:func:`coordinates`, per flight, natural log so that "1.6x faster" is a
distance of log 1.6 = 0.47): RMS speed |v| (m/s), RMS body rate |omega| (rad/s), RMS
variation of the specific force's size |f| about its mean (m/s^2: how hard the thrust is
worked), each floored at :data:`FLOORS` (a hover's sensor noise level, so that hovering
flights do not sit at log 0 = -inf). The *envelope* is the references' range per coordinate;
a flight's distance outside it is the largest excess over the coordinates (:class:`Position`).

Trend (:func:`fit_trend`). The references' main axis of variation in these coordinates
(first principal direction, ``axis``; sign: speed increasing) gives each flight a scalar
place u. Over the references, each shared parameter's own value theta_j (one Gauss-Newton
step from the pooled value on flight j alone, standard error se_j: stage 3 of
:mod:`.calibrate`)
is regressed on u_j by weighted least squares (weights 1/se_j^2): slope b, variance var(b)
scaled by the fit's reduced chi^2 when above 1 (the between-flight scatter); each channel's
log mean-square residual (the lack-of-fit statistic) is regressed on u_j by ordinary least
squares: slope g_c, one residual spread s_g pooled over channels (C (n - 2) degrees of
freedom).

The reference model at a flight's place (:func:`local_reference`). Every shared value is the
trend's prediction at the flight's place, ``theta_ref + b (u - u_w)`` (u_w the references'
weighted mean place; clipped to the parameter's bounds), its variance ``var(b) (u - u_w)^2``
added to the between-flight scatter. Why: what a shared value absorbs of the physics the
model lacks depends on how the flight was flown, and the references show how (a quadratic
rate drag fitted as linear damping reads higher on faster-turning flights; a closed-loop
motor lag reads longer on slower ones). Inside the references' range
of places [u_min, u_max] their other statistics hold (the calibrated scatter and lack-of-fit
spread already contain how the references differ among themselves). A flight at
e = u - u_max > 0 (or u_min - u) beyond the outermost reference meets the model's
extrapolation, measured by the trend:

* the between-flight scatter grows further, by ``(b^2 + var(b)) e^2``: the trend itself may
  bend out there;
* the noise scale sigma_c grows by ``exp(max(0, g_c e) / 2)``: the residual the references'
  trend expects there is carried as noise (never narrowed: the sensor noise does not shrink
  on a slower flight), and the lack-of-fit mean moves by ``g_c e`` less that widening;
* the lack-of-fit spread, per channel, grows to
  ``sqrt(s^2 + s_g^2 e^2 / (S_uu (1 + 1/n)) + g_c^2 e^2)``: the regression's prediction term
  (S_uu the references' sum of squared places about their mean) and the trend's own move
  there, as for the shared values (a form error that grows with the motion may grow faster
  beyond the references than along them).

Per channel, a line of its own (:func:`fit_channel_lines`). The place u is one axis for all
channels; a flight may drive one channel harder than every reference while its place lies
inside their range (a fast flight's sideways force; CHANGELOG.md: Docstrings as contracts).
Each channel's log mean square is regressed on that channel's own excitation x_c
(:func:`excitation`: the log RMS of its signal about the flight's mean; specific force,
angular acceleration, rotor speed) by ordinary least squares: slope h_c, residual spread s_x
pooled over channels (C (n - 2) degrees of freedom). A flight whose x_c lies outside the
references' range expects at least the line's move there (in the lack-of-fit mean only, not
in the noise scale as the trend's move is: a flight's own effect may be what drives the
channel, and a wider noise would halve its reading's precision), and at least its prediction
spread (over the lack-of-fit test's sqrt(1 + 1/n)): what the references show of how that
channel's residual grows with how hard it is driven, with the line's own uncertainty, rather
than the pooled axis's average growth.

The move is read by a law, not the straight line (:func:`growth_law`). A reference's mean
square is noise plus the model's error; an error in proportion to the signal grows as
e^(2 x), the noise does not: ms = t ((1 - f) + f e^(2 d)), d = x_c - mean(x_c), t the
references' typical mean square and f the share of it that grows, whose log-log slope at
their mean is 2 f. So f = clip(h_c / 2, 0, 1) and the move is log((1 - f) + f e^(2 d)),
never below the line's h_c d. Within the references the two agree to first order (the line
is the law's tangent at d = 0; at h_c = 0 and 2 they are the same); beyond them the straight
line of a log mean square falls short wherever an error below the noise grows into view
(slope 0.12, d = 1.81: the law's 1.14 against the line's 0.21; the measured case: CHANGELOG.md,
"A channel driven beyond every reference"). The prediction spread is
``s_x sqrt(1 + 1/n + L^2 / S_xx)``, L = d(move)/d(h_c) the law's lever on the slope's
uncertainty (|d| for the straight line, never below it).

A second line per noise-biased parameter (:data:`quadsim.gap.calibrate.NOISE_BIASED`): its
inverse information per sample q_j = se_j^2 N_j (:func:`quadsim.gap.calibrate.inverse_information`).
Least squares biases a value scaling a noisy regressor by the noise over the regressor's
signal (errors in variables), a straight line in q, not in u: over the references the same
weighted regression on q (where their q spread over at least :data:`MIN_INFO_SPREAD`, an
e-fold) gives slope b_q, var(b_q), and the two lines, with as many parameters, are compared
by their chi^2 (scaled by the better one's reduced chi^2 s): the q line's weight
``w = 1 / (1 + exp((chi2_q - chi2_u) / 2 s))``. At a flight with its own q (``info`` of
:func:`position`) the shared value moves by ``(1 - w) m_u + w m_q``, its variance
``(1 - w) v_u + w v_q + w (1 - w) (m_u - m_q)^2`` (each line's v with its extrapolation
beyond the outermost reference, e_q = q - clip(q, q_min, q_max) for the q line).

Where the trend is not extrapolated (:attr:`Trend.measured`, :func:`_predicted_move`). The
trend's slopes are measured over the references' span of places; a flight beyond them reads
the line there only where the references also measure how their model's lack of fit grows
along their axis: ``REACH_Z s_g / sqrt(S_uu) <= PROPORTIONAL_SLOPE``, the reach's rule below
on the trend's own axis (se of the growth g_c, the same pooled standard error as
:func:`slope_errors`). References flown alike (one speed group of the real Crazyflie flights:
places spanning 0.05-0.12, 1.96 se = 2.6-9.7) do not; references flown over a factor 3 do
(1.96 se = 0.3). Where they do not, or where the flight lies beyond their reach
(:func:`reach_of`), each shared value is the line's value at the nearest outermost reference,
``theta_ref + b (clip(u) - u_w)``, its variance ``var(b) (clip(u) - u_w)^2``, without the
extrapolation term: a slope measured over a span of places tens of times narrower than the
flight's distance extrapolates a noise slope, and its variance carried that far frees the
vehicle's own constants (thrust per Omega^2 by 17 %, so that the gravity balance no longer
pins a payload's mass) where the references simply did not vary. What the reference
model's error may be out there is the reach's allowance (below), not a difference of the
shared values; the lack-of-fit terms above (noise scale, spread) still widen by the trend.

No threshold decides "inside" or "outside" beyond the references' own extreme: the answer
states the distance whenever it is above zero. Below :data:`MIN_FLIGHTS` references (3: a
slope needs a residual degree of freedom) or when the references' places spread less than
:data:`MIN_SPREAD` (0.05, 5 %: no trend can be measured) the reference model is used as
calibrated, and the answer says that the references do not show how their model
extrapolates.

Example::

    >>> pos = position(flight.fit, ref.envelope)
    >>> pos.distance, pos.text          # 0.35, "speed 1.42x the fastest reference's ..."
    >>> local = local_reference(ref, pos)      # the Reference this flight is judged by

The reach
---------

How far beyond its references a flight can be judged by what they show (:func:`reach_of`,
:class:`Reach`; the judgment's rule 1c, :func:`quadsim.gap.judge.beyond_reach`).

The trend and the channel lines above extrapolate the references' own growth: a slope
measured over their spread. References flown alike (five copies of one test flight) spread
by a few per cent, and a flight flown 2-7x harder than them lies tens of their spreads
beyond: there the slopes say nothing, and the reference model's error at the flight's place
is unknown. Whether the references measure that growth is read from their own data: per
envelope coordinate k, the standard error se_k of the slope of their log mean squares on
x_k (ordinary least squares per channel, the residual spread pooled over the channels,
C (n - 2) degrees of freedom; :func:`slope_errors`). The growth is *measured* when
``REACH_Z se_k <= PROPORTIONAL_SLOPE`` (1.96 x se_k within 2): the references' 95 % interval
of the slope is narrower than the slope of the simplest way a model's error grows, in
proportion to the signal it predicts (residual RMS proportional to the excitation, its mean
square to the excitation squared: slope 2). Where it is, they can tell that growth from
none, and the trend and lines above hold (the real Crazyflie references' values:
docs/gap.md, "Few or narrow references").

A flight outside the references' envelope along a coordinate whose growth they do not
measure is *beyond their reach*. There the reference model's own error may be what a model
error growing in proportion to the flight's excitation gives: on channel c, with the
flight's log excitation e_c beyond the references' largest (:func:`excitation`; 0 within)
and their typical mean square t_c (exp of their mean log mean square, in the placed model's
sigma_c^2 units), an *allowance* of mean square ``a_c = t_c (exp(2 e_c) - 1)`` above t_c.
The judgment then counts, of each named reading's log-evidence margin, the part that its
removal of the gap within the allowance earns (the flight's effective samples N / tau_c
times half that removal, :attr:`Reach.counts`) as the model's error, not the vehicle's
difference (:func:`quadsim.gap.judge.extrapolation_share`). No threshold is tuned: the
slope 2 is the proportional law, 1.96 the two-sided 95 % quantile. Below 3 references no slope is
measurable and every coordinate is unmeasured.

Below the references. A flight flown more gently than every reference, along a coordinate
whose growth they do not measure, meets the opposite unknown. With k_c = exp(-under_c) < 1
its excitation of channel c over the references' smallest (``under_c`` the log distance,
:attr:`Reach.under`), the references cannot tell a lack of fit that shrinks in proportion to
the signal (slope 2: mean square t_c k_c^2 there) from one that does not shrink at all
(slope 0: t_c wherever the flight is flown -- an offset, a dead band, or a shared value such
as the inertia or a damping fitted where the references drive the body hard, read where the
flight barely excites it). Between the two laws lies t_c (1 - k_c^2): a systematic error
of the reference model that may still be on the flight where the proportional law would
have it gone, and a reading that removes it fits the model's own error, not a difference
of the vehicle. So, on each channel driven under every reference, what a named reading
removes of the mean square "no difference" leaves *under* the typical level,
max(0, min(m0_c, t_c) - m_c), counts as the model's error up to the allowance
``t_c (1 - exp(-2 under_c))`` (:attr:`Reach.allowance_under`; the judgment's share,
:func:`quadsim.gap.judge.extrapolation_share`). It mirrors the allowance above: there the
proportional law is the larger, t_c (k^2 - 1) above t_c; here the constant one, t_c (1 -
k^2) under it. What a reading removes above the typical level stays its own (a payload's
force or a CoM offset's steady moment leave a gentle flight's gap far above the references'
level), and the lack-of-fit test is unchanged (nothing under the typical level is a lack of
fit). No threshold is tuned: the slope 2 and 1.96 as above; the channels are those the
flight drives under every reference, and only where it lies below them along an unmeasured
coordinate (a flight above them in one coordinate and gentler in one channel keeps the
rule above alone).

Example::

    >>> reach = reach_of(ref, pos)       # None within reach
    >>> reach.coordinate, reach.ratio    # "thrust", 39.0 (times the references' spread)
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.optimize import brentq
from scipy.special import digamma, polygamma

from ..core.errors import ModelError
from ..core.frames import rotate_inverse
from ..vehicle.params import VehicleParams
from .fitting import Candidate, parameter_bounds, residuals, typical_scales
from .residual import MAP_WINDOW_S

__all__ = ["moderated_spread", "FORCE_FEATURES", "MOMENT_FEATURES", "RIDGE", "Discrepancy",
           "centre_term", "columns", "features", "fit_discrepancy", "FD_STEP", "LackOfFitBaseline",
           "Reference", "aligned", "jacobian", "read_later", "rotor_spectra", "shifted",
           "weighted_residual", "COORDINATES", "FLOORS", "MIN_FLIGHTS", "MIN_SPREAD", "Envelope",
           "Position", "Trend", "coordinates", "envelope_of", "envelope_summary", "fit_trend",
           "local_reference", "position", "ChannelLines", "excitation", "fit_channel_lines",
           "growth_law",
           "Reach", "reach_of", "slope_errors", "PROPORTIONAL_SLOPE", "REACH_Z"]


def _trigamma(x):
    return polygamma(1, x)


def moderated_spread(log_ms: np.ndarray) -> tuple[np.ndarray, int, tuple[float, int]]:
    """(spread per channel (C,), its degrees of freedom, (pooled spread, its degrees of
    freedom)) of ``log_ms`` (n flights, C channels) about each channel's mean, moderated
    towards the channels' common spread (module doc)."""
    log_ms = np.asarray(log_ms, dtype=float)
    n, channels = log_ms.shape
    d = n - 1
    pooled_dof = max(1, channels * d)
    pooled = float(np.sum((log_ms - log_ms.mean(axis=0)) ** 2) / pooled_dof)
    common = (float(np.sqrt(pooled)), pooled_dof)
    if d < 1 or channels < 3:
        return np.full(channels, np.sqrt(pooled)), pooled_dof, common
    var = np.maximum(log_ms.var(axis=0, ddof=1), 1e-12 * max(pooled, 1e-300))
    e = np.log(var) - digamma(d / 2) + np.log(d / 2)
    excess = float(np.var(e, ddof=1) - _trigamma(d / 2))
    if excess <= 0:
        return np.full(channels, np.sqrt(pooled)), pooled_dof, common
    # trigamma is decreasing on (0, inf): one root, bracketed from 1e-6 to where it is tiny
    nu0 = 2.0 * brentq(lambda x: _trigamma(x) - excess, 1e-6, 1e7)
    s0 = float(np.exp(np.mean(e) + digamma(nu0 / 2) - np.log(nu0 / 2)))
    moderated = (nu0 * s0 + d * var) / (nu0 + d)
    return np.sqrt(moderated), int(min(pooled_dof, round(nu0 + d))), common


#: the force channels' features (names; units m^2/s^2, rad/s^2); "#" is the channel's axis
FORCE_FEATURES = ("|v|v_#", "wd_x", "wd_y", "wd_z")
#: the moment channels' features (names; units m/s, rad/s, rad/s^2)
MOMENT_FEATURES = ("v_x", "v_y", "v_z", "w_x", "w_y", "w_z", "wd_x", "wd_y", "wd_z")
#: ridge added to the between-flight covariance, times its diagonal: a covariance of n
#: flights has rank n - 1 at most, and two features that move together on every reference
#: (v and |v|v at one speed) give a direction of no spread; 10 % keeps every direction's
#: spread at least a third of its own column's, so no direction is known better than the
#: references' per-flight fits know it
RIDGE = 0.1


@dataclass(frozen=True)
class Discrepancy:
    """The references' systematic residual on flight-state features (module doc).

    ``channels`` (tuple of int): the residual channels the term covers (0..5: Fx..Mz, 6..:
    the rotor speeds, with commands);
    ``names[k]``: channel ``channels[k]``'s feature names; ``centre[k]`` (F_k,): the mean
    coefficient beta_bar (channel unit per feature unit: N s/m, N s^2/m^2, N m s/m, N m s,
    N m s^2; rad/s per command unit); ``factor[k]`` (F_k, F_k): a lower-triangular L with L
    Lᵀ = Sigma_c, the coefficients' predictive covariance; ``flights``: how many references
    it was fitted on; ``explained`` (C,): the share of each channel's reference mean square
    the centre explains (0..1; 0 for channels it does not cover)."""

    channels: tuple
    names: tuple
    centre: tuple
    factor: tuple
    flights: int
    explained: np.ndarray
    #: per covered channel, each reference flight's coefficients (n, F_k): what
    #: :meth:`without` leaves one of out
    coefs: tuple = ()
    #: per covered channel (F_k,): the value each feature is taken from (phi - offset; the
    #: references' mean command level on a rotor channel, 0 elsewhere); () for none
    offsets: tuple = ()
    #: per covered channel, each reference's coefficient variances from its own noise
    #: (n, F_k) where the covariance is a random effect's (:func:`_from_coefs`), else None
    noise: tuple = ()

    def without(self, j: int) -> Discrepancy | None:
        """The term fitted on every reference but the ``j``-th (its coefficients left out;
        the channels and explained shares kept): the self-check's leave-one-out reference
        (:mod:`quadsim.gap.calibrate`). Every channel stays, even where F flights remain
        (the :data:`RIDGE` keeps the covariance positive): the noise model the flight is
        judged with is that of the residual after every channel's centre. None where fewer
        than 2 flights would remain."""
        if not self.coefs or len(self.coefs[0]) - 1 < 2:
            return None
        return _from_coefs(self.channels, self.names,
                           [np.delete(c, j, axis=0) for c in self.coefs], self.explained,
                           self.offsets, tuple(None if v is None else np.delete(v, j, axis=0)
                                               for v in self.noise))

    @property
    def covers_motion(self) -> bool:
        """Whether the term covers a force or moment channel (0..5): what the references
        share of the vehicle's motion, not only of its rotor channels (those take 2
        references, a force channel 5)."""
        return any(c < 6 for c in self.channels)

    @property
    def size(self) -> int:
        """Number of marginalised columns (the sum of the channels' feature counts)."""
        return int(sum(len(c) for c in self.centre))

    def to_json(self, channel_names) -> dict:
        """Channel name -> {feature: [centre, spread]} (SI), and the explained shares."""
        out = {}
        for c, names, centre, factor in zip(self.channels, self.names, self.centre,
                                            self.factor):
            spread = np.sqrt(np.sum(factor ** 2, axis=1))
            out[channel_names[c]] = {n: [float(m), float(s)]
                                     for n, m, s in zip(names, centre, spread)}
        return {"features": out, "flights": self.flights,
                "explained": {channel_names[c]: float(self.explained[c])
                              for c in self.channels}}


def features(states) -> dict[str, np.ndarray]:
    """Feature name -> (N,) values on ``states`` (:class:`quadsim.gap.residual.FlightStates`):
    the module doc's features, v_b = R(q)ᵀ v (ground velocity in body axes; the references'
    wind is small against the speeds flown); with commands, ``u_k`` (k = 1..R): rotor k's
    command level, its moving mean over :data:`quadsim.gap.residual.MAP_WINDOW_S` (edges
    padded with the nearest sample), uncentred (:class:`Discrepancy` keeps the offset)."""
    vb = rotate_inverse(states.quat, states.velocity)
    speed = np.linalg.norm(vb, axis=1)
    out = {}
    for i, axis in enumerate("xyz"):
        out[f"v_{axis}"] = vb[:, i]
        out[f"|v|v_{axis}"] = speed * vb[:, i]
        out[f"w_{axis}"] = states.body_rate[:, i]
        out[f"wd_{axis}"] = states.body_accel[:, i]
    if getattr(states, "command", None) is not None:
        for k, level in enumerate(command_level(states).T):
            out[f"u_{k + 1}"] = level
    return out


def command_level(states) -> np.ndarray:
    """(N, R) each rotor's command averaged over :data:`quadsim.gap.residual.MAP_WINDOW_S`
    (a centred moving mean; the window at least one sample, the edges padded with the
    nearest sample): the level the static map is read at, without the manoeuvres that the
    rotor channel's dynamics (motor lag, timing) read."""
    from scipy.ndimage import uniform_filter1d

    command = np.asarray(states.command, dtype=float)
    dt = float(states.t[1] - states.t[0]) if len(states.t) > 1 else MAP_WINDOW_S
    width = max(1, int(round(MAP_WINDOW_S / dt)))
    return uniform_filter1d(command, width, axis=0, mode="nearest")


def _design(states, names: tuple, memo: dict | None = None,
            offset: np.ndarray | None = None) -> np.ndarray:
    """(N, F) features ``names`` on ``states`` less ``offset`` (F,) (None: none), kept in
    ``memo`` per motion and command arrays."""
    if memo is None:
        f = features(states)
        x = np.column_stack([f[n] for n in names])
        return x if offset is None else x - offset
    command = getattr(states, "command", None)
    key = ("discrepancy.features", id(states.velocity), id(states.body_accel),
           id(command), names, None if offset is None else offset.tobytes())
    hit = memo.get(key)
    if hit is not None and hit[0] is states.velocity and hit[1] is states.body_accel \
            and hit[2] is command:
        return hit[3]
    f = features(states)
    x = np.column_stack([f[n] for n in names])
    if offset is not None:
        x = x - offset
    memo[key] = (states.velocity, states.body_accel, command, x)
    return x


def channel_features(channel: int) -> tuple:
    """The feature names of residual channel ``channel`` (0..2 forces, 3..5 moments, 6 on
    rotor k = channel - 5's speed: its command level ``u_k``)."""
    if channel < 3:
        return tuple(n.replace("#", "xyz"[channel]) for n in FORCE_FEATURES)
    if channel < 6:
        return MOMENT_FEATURES
    return (f"u_{channel - 5}",)


def fit_discrepancy(residual_list, states_list, levels=()) -> Discrepancy | None:
    """The :class:`Discrepancy` of the reference model's residuals ``residual_list`` (each
    (N_j, C), SI) on the reference ``states_list`` (module doc). A channel with F features
    is covered from F + 1 flights on (below, its coefficients' between-flight covariance is
    not of full rank: the force channels from 5 references, the moments from 10, a rotor's
    level from 2); None where no channel is. ``levels`` (per rotor, bool): whether rotor
    k's channel takes its command level as a feature (every flight logging commands):
    where the reference model's map for it is a gain through the origin
    (:func:`quadsim.gap.residual.proportional_rotors`), its slope at the references' level
    an assumption, not the data's."""
    n = len(states_list)
    if n < 3:
        return None
    chans = residual_list[0].shape[1]
    commands = all(getattr(s, "command", None) is not None for s in states_list)
    channels, names, coefs_all, offsets, noise = [], [], [], [], []
    explained = np.zeros(chans)
    for c in range(chans if commands else min(chans, 6)):
        if c >= 6 and not (c - 6 < len(levels) and levels[c - 6]):
            continue                # that rotor's map slope is the data's (or no level)
        feats = channel_features(c)
        if n < len(feats) + 1:      # a covariance of F coefficients needs F + 1 flights
            continue
        offset = None
        if c >= 6:                  # a rotor's level: taken from the references' mean
            offset = np.mean(np.concatenate([_design(s, feats) for s in states_list]),
                             axis=0)
        designs = [_design(s, feats, offset=offset) for s in states_list]
        coefs = np.array([np.linalg.lstsq(x, r[:, c], rcond=None)[0]
                          for x, r in zip(designs, residual_list)])
        channels.append(c)
        names.append(feats)
        coefs_all.append(coefs)
        offsets.append(np.zeros(len(feats)) if offset is None else offset)
        noise.append(None if offset is None else np.array(
            [own_noise(x, r[:, c], b) for x, r, b in zip(designs, residual_list, coefs)]))
        centre = coefs.mean(axis=0)
        before = sum(float(np.sum(r[:, c] ** 2)) for r in residual_list)
        after = sum(float(np.sum((r[:, c] - x @ centre) ** 2))
                    for x, r in zip(designs, residual_list))
        explained[c] = max(0.0, 1.0 - after / before) if before > 0 else 0.0
    if not channels:
        return None
    return _from_coefs(tuple(channels), tuple(names), coefs_all, explained, tuple(offsets),
                       tuple(noise))


def own_noise(x: np.ndarray, r: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """(F,) the variances of one flight's least-squares coefficients ``coef`` of ``r`` (N,)
    on the design ``x`` (N, F) from its own noise: ``s^2 tau diag((xᵀx)^-1)``, s^2 the
    residual's mean square over N - F degrees of freedom and tau its integrated
    autocorrelation time (samples, :func:`quadsim.gap.fitting.correlation_time`: a
    correlated residual carries N / tau independent samples)."""
    from .fitting import correlation_time

    e = r - x @ coef
    dof = max(1, len(r) - x.shape[1])
    s2 = float(e @ e) / dof * correlation_time(e)
    return s2 * np.diag(np.linalg.pinv(x.T @ x))


def _from_coefs(channels: tuple, names: tuple, coefs_all: list, explained: np.ndarray,
                offsets: tuple = (), noise: tuple = ()) -> Discrepancy:
    """The :class:`Discrepancy` of per-flight coefficients ``coefs_all`` (per channel
    (n, F)): their mean, and their predictive covariance with the :data:`RIDGE`;
    ``offsets`` the features' (:attr:`Discrepancy.offsets`).

    The predictive covariance, per channel: where ``noise`` gives none (the force and moment
    channels: aerodynamics that drift with how each flight is flown), the coefficients'
    sample covariance times (1 + 1/n), their scatter kept whole. Where it gives each
    flight's coefficient variances from its own noise (n, F) (a rotor's command level: one
    property of the motor map, the hardware every flight shares), the method-of-moments
    random effect as the calibration's between-flight scatter is read
    (:mod:`quadsim.gap.calibrate`, stage 3): ``tau^2 = max(0, var_j(beta_j) - mean_j se_j^2)``
    per feature, plus the mean's own uncertainty ``var_j(beta_j) / n``: what a new flight's
    coefficient may be. Why: references flown at one level determine their slope poorly
    (their per-flight estimates scatter by their noise, not by the vehicle), and that
    scatter taken whole would let the feature take any flight's steady rotor offset (its
    level differs from theirs by a constant over the flight) as what the references cannot
    tell (measured: CHANGELOG.md, "A rotor's command level")."""
    centres, factors = [], []
    noise = noise or (None,) * len(coefs_all)
    for coefs, own in zip(coefs_all, noise):
        n, f = coefs.shape
        cov = np.cov(coefs, rowvar=False).reshape(f, f)
        if own is None:
            cov = cov * (1.0 + 1.0 / n)
        else:
            scatter = np.maximum(0.0, np.diag(cov) - np.mean(own, axis=0))
            cov = np.diag(scatter) + cov / n
        cov = cov + RIDGE * np.diag(np.diag(cov)) + 1e-30 * np.eye(f)
        centres.append(coefs.mean(axis=0))
        factors.append(np.linalg.cholesky(cov))
    return Discrepancy(channels, names, tuple(centres), tuple(factors), len(coefs_all[0]),
                       explained, tuple(coefs_all), tuple(offsets), tuple(noise))


def centre_term(states, discrepancy: Discrepancy | None, chans: int,
                memo: dict | None = None) -> np.ndarray | float:
    """phi_c(t)ᵀ beta_bar_c as (N, ``chans``) (SI; zero on the channels it does not cover),
    or 0.0 without a discrepancy: what the references' systematic residual predicts on this
    flight, taken off every residual. With a ``memo``, kept per motion arrays (velocity,
    body acceleration: what the features read), discrepancy and channel count: the same
    numbers for every evaluation on one flight."""
    if discrepancy is None:
        return 0.0
    if memo is not None:
        key = ("discrepancy.centre", id(states.velocity), id(states.body_accel),
               id(discrepancy), chans)
        hit = memo.get(key)
        if hit is not None and hit[0] is states.velocity and hit[1] is states.body_accel \
                and hit[2] is discrepancy:
            return hit[3]
    out = np.zeros((len(states.t), chans))
    for k, (c, names, centre) in enumerate(zip(discrepancy.channels, discrepancy.names,
                                               discrepancy.centre)):
        out[:, c] = _design(states, names, memo, _offset(discrepancy, k)) @ centre
    if memo is not None:
        memo[key] = (states.velocity, states.body_accel, discrepancy, out)
    return out


def _offset(discrepancy: Discrepancy, k: int) -> np.ndarray | None:
    """The ``k``-th covered channel's feature offset, None where it is zero (or not kept)."""
    if k >= len(discrepancy.offsets) or not np.any(discrepancy.offsets[k]):
        return None
    return discrepancy.offsets[k]


def columns(states, discrepancy: Discrepancy | None, weights: np.ndarray,
            memo: dict | None = None) -> np.ndarray:
    """The marginalised columns (N C, K) in the weighted residual's rows (row n C + c):
    channel c's features times its factor L_c times sqrt(weights_c) (``weights`` (C,):
    1 / (sigma_c^2 tau_c)), so that a unit shift of each column is one standard deviation of
    the coefficients' predictive covariance; (N C, 0) without a discrepancy."""
    chans = len(weights)
    n = len(states.t)
    if discrepancy is None:
        return np.zeros((n * chans, 0))
    out = np.zeros((n, chans, discrepancy.size))
    k = 0
    for j, (c, names, factor) in enumerate(zip(discrepancy.channels, discrepancy.names,
                                               discrepancy.factor)):
        x = _design(states, names, memo, _offset(discrepancy, j)) @ factor
        out[:, c, k:k + x.shape[1]] = x * np.sqrt(weights[c])
        k += x.shape[1]
    return out.reshape(n * chans, -1)


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

    speed, accel, *joined = spectra if spectra is not None else rotor_spectra(states)
    joined = joined[0] if joined else (           # (speed, accel) alone: joined here
        None if speed is None or accel is None else np.hstack([speed, accel]))
    if joined is not None:                          # both in one inverse transform
        both = read_later(states.t, None, delay_s, joined)
        k = speed.shape[1]
        return _with_rotors(states, np.ascontiguousarray(both[:, :k]),
                            np.ascontiguousarray(both[:, k:]))
    return dataclasses.replace(
        states, rotor_speed=read_later(states.t, states.rotor_speed, delay_s, speed),
        rotor_accel=None if states.rotor_accel is None
        else read_later(states.t, states.rotor_accel, delay_s, accel))


def _with_rotors(states, speed: np.ndarray, accel: np.ndarray):
    """``dataclasses.replace(states, rotor_speed=speed, rotor_accel=accel)`` for the frozen
    fit states (:class:`quadsim.gap.residual.FlightStates`, no ``__post_init__``): a shallow
    copy with the two fields set, the same object a replace builds at a tenth of its cost (a
    fit reads the rotor speeds at thousands of delays per flight)."""
    if type(states).__dict__.get("__post_init__") is not None or \
            not dataclasses.is_dataclass(states):
        return dataclasses.replace(states, rotor_speed=speed, rotor_accel=accel)
    out = copy.copy(states)
    object.__setattr__(out, "rotor_speed", speed)
    object.__setattr__(out, "rotor_accel", accel)
    return out


def rotor_spectra(states) -> tuple:
    """The mirrored spectra :func:`read_later` shifts, of the rotor speeds and their
    derivative (None each on a non-uniform time base or where the signal is missing), and
    both side by side (speeds' columns first; None unless both are there): one flight's,
    computed once and passed to every :func:`shifted` of it."""
    speed = _spectrum(states.t, states.rotor_speed)
    accel = None if states.rotor_accel is None else _spectrum(states.t, states.rotor_accel)
    joined = None if speed is None or accel is None else np.hstack([speed, accel])
    return speed, accel, joined


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
    # 2 pi i nu (nu: cycles per sample), kept per length: the same product as
    # ``2j * np.pi * np.fft.rfftfreq(2 * n)[:, None]``, taken once
    return np.fft.irfft(spectrum * np.exp(_phase_rate(2 * n) * (delay_s / dt)), 2 * n,
                        axis=0)[:n]


@lru_cache(maxsize=64)
def _phase_rate(length: int) -> np.ndarray:
    """``2j * pi * rfftfreq(length)[:, None]`` (read-only), the phase per sample of delay
    of each frequency of a series of ``length`` samples (:func:`read_later`)."""
    out = 2j * np.pi * np.fft.rfftfreq(length)[:, None]
    out.flags.writeable = False
    return out


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
      references' static command -> speed map (:func:`quadsim.gap.residual.fit_motor_map`)
      where commands are logged.
    - ``rotor``: whether the rotor-speed channels are part of the residual (commands logged
      on every reference flight; :mod:`quadsim.gap.residual`).
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
      channel, :mod:`quadsim.gap.reference`); ``lof_dof``: its degrees of freedom;
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
    #: the references' envelope and the model's trend along it (:mod:`.reference`)
    envelope: object = None
    #: the references' mean battery voltage (V; None without a voltage log): the voltage at
    #: which their speed per command holds (:func:`voltage_spread`)
    vbat_ref: float | None = None
    #: shared parameter -> "lower" or "upper" where the references' pooled fit stopped at
    #: that bound (:func:`bounded`): their data say only that the value lies at or beyond it
    at_bound: dict = field(default_factory=dict)
    #: (lower, upper) bounds of the shared parameters in the references' fit
    #: (:func:`fit_bounds`): the reference model at a flight's place stays within them
    #: (:func:`quadsim.gap.reference.local_reference`); None: the effects' plausible ranges
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
    #: speed map implies for a propeller change (:func:`quadsim.gap.residual.load_exponent`);
    #: None where their commands do not span enough to say
    load_exponent: tuple | None = None
    #: (spread, degrees of freedom) of the lack of fit pooled over the channels: what a
    #: flight outside the references' envelope is tested with at least
    #: (:mod:`quadsim.gap.reference`); None: ``lof_sd`` is the pooled spread already
    lof_pooled: tuple | None = None
    #: at a flight's place (:func:`quadsim.gap.reference.local_reference`), (mean (C,),
    #: spread (C,)): the lack-of-fit statistics had the channel lines been read as straight
    #: lines, where :func:`quadsim.gap.reference.growth_law` expects more (a residual beyond
    #: these and within ``lof_mean``/``lof_sd`` is the judgment's "grown": not sure); None
    #: where the two agree
    lof_line: tuple | None = None
    #: the lack-of-fit baseline from flights other than the references (held-out mode's
    #: training flights, :class:`LackOfFitBaseline`); None: ``lof_mean``/``lof_sd``/``lof_dof``
    baseline: LackOfFitBaseline | None = None
    #: the references' systematic residual on flight-state features, with its between-flight
    #: covariance (:class:`quadsim.gap.reference.Discrepancy`): taken off every residual
    #: (:func:`weighted_residual`) and marginalised with every explanation
    #: (:class:`quadsim.gap.evidence.Problem`); None: none (fewer than 3 references, or a
    #: parameter-set reference)
    discrepancy: object = None
    #: (n, C) each reference flight's log(ms_jc / sigma_c^2) (the lack-of-fit baseline's
    #: data, ``lof_mean`` their mean): what the self-check leaves one flight out of
    #: (:mod:`quadsim.gap.calibrate`); None where not kept
    log_ms: np.ndarray | None = None
    #: a callable (residual (N, C), params, effects) -> (N, C) applied after the discrepancy's
    #: centre and before the weights (:func:`weighted_residual`), or None: the calibration's
    #: roll and pitch residual on the torque side (:class:`quadsim.gap.calibrate.TorqueSide`),
    #: set only on the copies its own fits read
    side: object = None
    #: the self-check of the references against each other
    #: (:class:`quadsim.gap.calibrate.SelfCheck`): what a reading's size is compared with
    #: (practical significance); None before it ran or without one
    self_check: object = None
    #: the references left out of this model (:func:`quadsim.gap.calibrate.odd_references`):
    #: (name, verdict, channels) of each as the first self-check judged it against the others
    left_out: tuple = ()
    #: each reference flight's own fit (:class:`quadsim.gap.calibrate.PerFlight`): what the
    #: between-flight scatter and the envelope are built from, kept for the self-check;
    #: None where not kept
    per_flight: object = None
    #: the flight's :class:`Position` this model is placed at (:func:`local_reference`):
    #: where the references' readings are compared too
    #: (:func:`quadsim.gap.calibrate.placed`); None: the model as calibrated
    place: object = None
    #: the flight's :class:`Reach` where it drives a channel beyond what the references can
    #: vouch for (:func:`local_reference`); None: within reach, or the model as calibrated
    reach: object = None

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
    (:func:`quadsim.gap.reference.centre_term`)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor, memo=memo)
    r = r - centre_term(states, reference.discrepancy, r.shape[1], memo)
    if reference.side is not None:
        r = reference.side(r, reference.params, effects)
    return r * np.sqrt(reference.weights)


def jacobian(states, reference: Reference, columns: list[int], build, *,
             memo: dict | None = None, with_base: bool = False,
             base: np.ndarray | None = None):
    """Forward-difference Jacobian (N C, len(columns)) of the weighted residual with respect
    to the shared parameters ``columns`` at theta_ref (``build(theta)`` -> effects);
    ``with_base``: (Jacobian, the weighted residual at theta_ref, flattened). The columns
    share the residual parts one parameter does not move (the rotations, the measured
    wrench of one vehicle, the rotor channel of one command -> speed model) through
    ``memo`` (a new one per call by default). ``base``: that weighted residual (N C,) where
    already computed (the same numbers: it is not computed again)."""
    memo = {} if memo is None else memo
    typical = typical_scales(reference.candidate, reference.params)
    _, upper = parameter_bounds(reference.candidate, reference.params)
    if base is None:
        base = weighted_residual(states, reference, build(reference.theta), memo).ravel()
    out = np.empty((base.size, len(columns)))
    for j, k in enumerate(columns):
        h = FD_STEP * typical[k]
        at_upper = reference.theta[k] + h > upper[k]
        if at_upper:      # a value at its upper bound: step down
            h = -h
        try:
            moved = _probe(states, reference, build, memo, k, h)
        except ModelError:      # the step crosses a wall of the physical set: the other way
            if at_upper:        # pinned both ways (its bound above, the wall below): it
                out[:, j] = 0.0     # cannot move at theta_ref, a zero column
                continue
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


#: the envelope's coordinates (name, unit, what it measures)
COORDINATES = (("speed", "m/s", "RMS speed"), ("rate", "rad/s", "RMS body rate"),
               ("thrust", "m/s^2", "RMS variation of the specific force's size"))
#: floors of the coordinates (m/s, rad/s, m/s^2): a hover's level (5 cm/s drift, 3 deg/s
#: gyro noise and wobble, 0.05 m/s^2 accelerometer noise)
FLOORS = np.array([0.05, 0.05, 0.05])
#: fewest references with which a trend is measured
MIN_FLIGHTS = 3
#: least spread (natural log units) of the references' places along their axis
MIN_SPREAD = 0.05
#: least spread (natural log units) of the references' inverse information per sample of a
#: parameter for its inverse-information form: an e-fold. Below it the line's slope comes
#: from a range of information narrower than that of the differences it would explain and
#: extrapolates a noise slope (a parameter whose information does not depend on how a
#: flight is flown spreads far less than an e-fold)
MIN_INFO_SPREAD = 1.0


def coordinates(states) -> np.ndarray:
    """Envelope coordinates (3,) of a flight's states: natural logs (module doc)."""
    speed = np.sqrt(np.mean(np.sum(states.velocity ** 2, axis=1)))
    rate = np.sqrt(np.mean(np.sum(states.body_rate ** 2, axis=1)))
    size = np.linalg.norm(states.specific_force, axis=1)
    thrust = np.sqrt(np.mean((size - size.mean()) ** 2))
    return np.log(np.maximum([speed, rate, thrust], FLOORS))


def excitation(states) -> np.ndarray:
    """Per residual channel, how hard the flight drives it (natural log of an RMS about the
    flight's mean, floored at 1e-9 of its unit): Fx, Fy, Fz the specific force's body
    components (m/s^2), Mx, My, Mz the body angular acceleration's (rad/s^2), then each
    rotor's speed (rad/s) where the flight logs rotor speeds: (6,) or (6 + R,)."""
    def rms(x):
        x = np.asarray(x, float)
        return np.sqrt(np.mean((x - x.mean(axis=0)) ** 2, axis=0))
    parts = [rms(states.specific_force), rms(states.body_accel)]
    if states.rotor_speed is not None:
        parts.append(rms(states.rotor_speed))
    return np.log(np.maximum(np.concatenate(parts), 1e-9))


@dataclass(frozen=True)
class ChannelLines:
    """The references' lack of fit per channel against the flight's own excitation of that
    channel (module doc, "The envelope"): each channel's log mean square regressed on its
    :func:`excitation` by ordinary least squares over the n references. ``mean`` (C,) the
    references' mean excitation, ``slope`` (C,) d(log ms_c)/d(excitation_c), ``s_xx`` (C,)
    sum of squared excitations about their mean, ``low``/``high`` (C,) the references'
    range, ``sd`` the residual spread pooled over channels (``dof`` = C (n - 2)), ``n``."""

    mean: np.ndarray
    slope: np.ndarray
    s_xx: np.ndarray
    low: np.ndarray
    high: np.ndarray
    sd: float
    dof: int
    n: int

    def beyond(self, x: np.ndarray, *, straight: bool = False
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At a flight's excitation ``x`` (C,): (beyond (C,) bool: outside the references'
        range, move (C,) the line's log mean square over the references' mean there, read
        by :func:`growth_law` (``straight``: the straight line's slope d), spread (C,) its
        prediction spread over sqrt(1 + 1/n), as the lack-of-fit spreads are:
        sd sqrt(1 + L^2 / (S_xx (1 + 1/n))), d = x - mean, L the law's lever (|d|
        straight))."""
        x = np.asarray(x, float)
        d = x - self.mean
        move, lever = (self.slope * d, np.abs(d)) if straight else growth_law(self.slope, d)
        spread = self.sd * np.sqrt(1.0 + lever ** 2 / (np.maximum(self.s_xx, 1e-300)
                                                        * (1.0 + 1.0 / self.n)))
        return (x > self.high) | (x < self.low), move, spread


def growth_law(slope: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A channel's log mean square ``d`` log excitation units from the references' mean,
    by the noise-plus-proportional-error law (module doc, "The envelope"): ms = t ((1 - f) +
    f e^(2 d)), f = clip(slope / 2, 0, 1) the share of the references' typical mean square t
    that grows in proportion to the excitation (slope: the line's d(log ms)/d(excitation)
    at their mean, 2 f under the law). Returns (move (C,), the law's log ms over log t and
    never below the line's ``slope d``; lever (C,), d(move)/d(slope) and never below |d|,
    what the slope's standard error is multiplied by in the prediction spread)."""
    slope = np.asarray(slope, float)
    d = np.asarray(d, float)
    share = np.clip(slope / PROPORTIONAL_SLOPE, 0.0, 1.0)
    grow = np.expm1(PROPORTIONAL_SLOPE * d)
    level = np.maximum(1.0 + share * grow, 1e-300)
    move = np.maximum(slope * d, np.log(level))
    lever = np.maximum(np.abs(grow / (PROPORTIONAL_SLOPE * level)), np.abs(d))
    return move, lever


def fit_channel_lines(excite: np.ndarray | None, log_ms: np.ndarray) -> ChannelLines | None:
    """The :class:`ChannelLines` of n references: ``excite`` (n, C') their
    :func:`excitation` (its first C columns used; None: not measured), ``log_ms`` (n, C)
    their log mean squares over sigma_c^2. None below :data:`MIN_FLIGHTS` references,
    without an excitation for every channel, or where a channel's excitations do not spread
    (their range below :data:`MIN_SPREAD`: no slope can be measured)."""
    if excite is None:
        return None
    excite = np.asarray(excite, float)
    log_ms = np.asarray(log_ms, float)
    n, c = log_ms.shape
    if n < MIN_FLIGHTS or excite.ndim != 2 or excite.shape[0] != n or excite.shape[1] < c:
        return None
    x = excite[:, :c]
    if np.any(np.ptp(x, axis=0) < MIN_SPREAD):
        return None
    mean = x.mean(axis=0)
    dx = x - mean
    s_xx = np.sum(dx ** 2, axis=0)
    slope = np.sum(dx * (log_ms - log_ms.mean(axis=0)), axis=0) / s_xx
    rest = log_ms - log_ms.mean(axis=0) - dx * slope
    dof = max(1, c * (n - 2))
    return ChannelLines(mean, slope, s_xx, x.min(axis=0), x.max(axis=0),
                        float(np.sqrt(np.sum(rest ** 2) / dof)), dof, n)


@dataclass
class Trend:
    """How the references' shared values and residuals move along their axis (module doc).

    ``axis`` (3,): unit direction in the coordinates; ``u_mean``: the references' mean place;
    ``u_w`` (P,): per parameter the weighted mean place; ``slope``/``slope_var`` (P,): dtheta/du
    and its variance; ``lof_slope`` (C,): d(log ms_c)/du; ``lof_mean`` (C,): at u_mean;
    ``lof_sd``, ``lof_dof``: pooled residual spread; ``s_uu``: sum of squared places about
    u_mean; ``n``: references; ``u_low``/``u_high``: the outermost references' places.
    The inverse-information form (module doc, per parameter; weight 0 where not measured):
    ``q_weight`` its posterior weight against the place's line, ``q_w``, ``q_slope``,
    ``q_slope_var``, ``q_low``/``q_high`` as their place counterparts."""

    axis: np.ndarray
    u_mean: float
    u_w: np.ndarray
    slope: np.ndarray
    slope_var: np.ndarray
    lof_slope: np.ndarray
    lof_mean: np.ndarray
    lof_sd: float
    lof_dof: int
    s_uu: float
    n: int
    u_low: float
    u_high: float
    q_weight: np.ndarray | None = None
    q_w: np.ndarray | None = None
    q_slope: np.ndarray | None = None
    q_slope_var: np.ndarray | None = None
    q_low: np.ndarray | None = None
    q_high: np.ndarray | None = None

    @property
    def growth_se(self) -> float:
        """Standard error of the slope of the references' log mean squares on their place
        u (log mean square per unit place): ``lof_sd / sqrt(s_uu)``, the pooled ordinary
        least-squares slope's (:func:`slope_errors` with u as the one regressor)."""
        return self.lof_sd / np.sqrt(self.s_uu)

    @property
    def measured(self) -> bool:
        """Whether the references measure how their model's lack of fit grows along their
        axis: ``REACH_Z growth_se <= PROPORTIONAL_SLOPE``, the reach's rule
        (:func:`reach_of`, module doc "The reach") on the trend's own axis. Where not, the
        trend does not extrapolate the shared values beyond the outermost reference
        (:func:`_predicted_move`)."""
        return bool(REACH_Z * self.growth_se <= PROPORTIONAL_SLOPE)


@dataclass
class Envelope:
    """The references' coordinates (n, 3) and their trend (None: not measurable)."""

    coords: np.ndarray
    trend: Trend | None
    #: the references' lack of fit against each channel's own excitation (None: not measured)
    lines: ChannelLines | None = None
    #: (n, C') each reference's :func:`excitation` (None: not measured): how far beyond them
    #: a flight drives each channel (:func:`reach_of`)
    excite: np.ndarray | None = None

    @property
    def low(self) -> np.ndarray:
        return self.coords.min(axis=0)

    @property
    def high(self) -> np.ndarray:
        return self.coords.max(axis=0)


@dataclass
class Position:
    """A flight's place: coordinates, distance outside the envelope (log units, 0 inside),
    the coordinate furthest outside, place u along the references' axis, and in words."""

    coords: np.ndarray
    distance: float
    worst: str
    u: float | None
    text: str
    #: the flight's own inverse information per sample of each shared parameter (P,)
    #: (:func:`quadsim.gap.calibrate.inverse_information`); None: not measured
    info: np.ndarray | None = None
    #: the flight's :func:`excitation` of each channel; None: not measured
    excite: np.ndarray | None = None
    #: the flight's number of fit samples (None: not known): with the noise model's
    #: correlation times, its effective sample count per channel (:class:`Reach`)
    samples: int | None = None

    def to_json(self) -> dict:
        names = [c[0] for c in COORDINATES]
        return {"outside": self.distance > 0, "distance": float(self.distance),
                "furthest": self.worst if self.distance > 0 else None,
                "rms": {n: float(np.exp(v)) for n, v in zip(names, self.coords)},
                "place": None if self.u is None else float(self.u), "text": self.text}


def envelope_of(coords: np.ndarray, values: np.ndarray, se: np.ndarray,
                identified: np.ndarray, log_ms: np.ndarray, *,
                info: np.ndarray | None = None, excite: np.ndarray | None = None
                ) -> Envelope:
    """The envelope of reference flights (coordinates (n, 3)), with the trend of their own
    parameter values ``values`` (n, P) (standard errors ``se``; parameters not
    ``identified`` get no slope), their log mean squares ``log_ms`` (n, C), their
    inverse information per sample ``info`` (n, P; None: no inverse-information form) and
    their :func:`excitation` ``excite`` (n, C'; None: no per-channel lines)."""
    return Envelope(np.asarray(coords, float),
                    fit_trend(np.asarray(coords, float), values, se, identified, log_ms,
                              info),
                    fit_channel_lines(excite, log_ms),
                    None if excite is None else np.asarray(excite, float))


def envelope_summary(envelope: Envelope | None, names=()) -> dict | None:
    """The references' envelope as JSON: per coordinate the smallest and largest RMS value
    (SI), whether a trend was measured, and per shared parameter (``names``) the weight of
    its inverse-information line where it has one."""
    if envelope is None:
        return None
    coords = [c[0] for c in COORDINATES]
    trend = envelope.trend
    weights = {} if trend is None or trend.q_weight is None else {
        n: float(w) for n, w in zip(names, trend.q_weight) if w > 0}
    return {"rms": {n: [float(np.exp(lo)), float(np.exp(hi))]
                    for n, lo, hi in zip(coords, envelope.low, envelope.high)},
            "trend": trend is not None, "information_line": weights}


def _line(x: np.ndarray, v: np.ndarray, se: np.ndarray) -> tuple[float, float, float, float]:
    """Weighted (1/se^2) line of v on x: weighted mean place x_w, slope b, var(b) scaled by
    the reduced chi^2 when above 1, and the fit's chi^2."""
    w = 1.0 / np.maximum(se, 1e-300) ** 2
    x_w = float(np.sum(w * x) / np.sum(w))
    dx = x - x_w
    sxx = float(np.sum(w * dx ** 2))
    mean = float(np.sum(w * v) / np.sum(w))
    b = float(np.sum(w * dx * (v - mean)) / sxx)
    chi2 = float(np.sum(w * (v - mean - b * dx) ** 2))
    return x_w, b, max(1.0, chi2 / (len(x) - 2)) / sxx, chi2


def fit_trend(coords, values, se, identified, log_ms, info=None) -> Trend | None:
    """The :class:`Trend` of n reference flights (module doc): ``coords`` (n, 3) their
    envelope coordinates (:func:`coordinates`), ``values``/``se`` (n, P) each flight's own
    shared values and standard errors (each parameter's unit), ``identified`` (P,) which
    parameters get a slope, ``log_ms`` (n, C) their log mean squares over sigma_c^2,
    ``info`` (n, P) their inverse information per sample (None: no inverse-information
    line). None below :data:`MIN_FLIGHTS` references or a spread of places below
    :data:`MIN_SPREAD`."""
    n = len(coords)
    if n < MIN_FLIGHTS:
        return None
    centred = coords - coords.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    if axis[0] < 0 or (axis[0] == 0 and axis.sum() < 0):
        axis = -axis
    u = coords @ axis
    if np.ptp(u) < MIN_SPREAD:
        return None
    p = values.shape[1]
    u_w, slope, slope_var = np.zeros(p), np.zeros(p), np.zeros(p)
    q = [np.zeros(p) for _ in range(6)]     # weight, q_w, slope, slope_var, low, high
    for k in range(p):
        # a standard error of 0 (or so small that its weight overflows) is a value the
        # flight's step did not move, not one known exactly: no line
        with np.errstate(divide="ignore", over="ignore"):
            weighable = np.all(np.isfinite(1.0 / se[:, k] ** 2))
        if not identified[k] or not weighable:
            u_w[k] = u.mean()
            continue
        u_w[k], slope[k], slope_var[k], chi2_u = _line(u, values[:, k], se[:, k])
        x = None if info is None else info[:, k]
        if x is None or not np.all(np.isfinite(x)) or np.any(x <= 0) \
                or np.ptp(np.log(x)) < MIN_INFO_SPREAD:
            continue
        q_w, b, var_b, chi2_q = _line(x, values[:, k], se[:, k])
        # the two lines have as many parameters: their likelihoods compare directly, the
        # chi^2 scaled by the better line's reduced chi^2 (the between-flight scatter
        # neither line explains, which must not turn a small difference into certainty)
        scale = max(1.0, min(chi2_u, chi2_q) / (n - 2))
        weight = 1.0 / (1.0 + np.exp((chi2_q - chi2_u) / (2.0 * scale)))
        for arr, val in zip(q, (weight, q_w, b, var_b, x.min(), x.max())):
            arr[k] = val
    du = u - u.mean()
    s_uu = float(du @ du)
    g = (du @ (log_ms - log_ms.mean(axis=0))) / s_uu
    lof_mean = log_ms.mean(axis=0)
    rest = log_ms - lof_mean - np.outer(du, g)
    dof = max(1, rest.size - 2 * rest.shape[1])
    return Trend(axis, float(u.mean()), u_w, slope, slope_var, g, lof_mean,
                 float(np.sqrt(np.sum(rest ** 2) / dof)), dof, s_uu, n,
                 float(u.min()), float(u.max()), *q)


def position(states, envelope: Envelope | None, info: np.ndarray | None = None
             ) -> Position | None:
    """A flight's :class:`Position` against the references' envelope (None without one);
    ``info``: its inverse information per sample of each shared parameter."""
    if envelope is None:
        return None
    x = coordinates(states)
    above, below = x - envelope.high, envelope.low - x
    excess = np.maximum(np.maximum(above, below), 0.0)
    worst = int(np.argmax(excess))
    distance = float(excess[worst])
    u = None if envelope.trend is None else float(x @ envelope.trend.axis)
    name, unit, what = COORDINATES[worst]
    if distance <= 0:
        text = "inside the reference flights' envelope (speed, body rate, thrust variation)"
    else:
        fast = above[worst] > 0
        ratio = np.exp(x[worst] - (envelope.high if fast else envelope.low)[worst])
        size = (f"{ratio:.2f}x" if abs(np.log(ratio)) >= 0.1
                else f"{100 * abs(ratio - 1):.1f} % {'above' if fast else 'below'}")
        text = (f"outside the reference flights' envelope: {what} {np.exp(x[worst]):.3g} "
                f"{unit}, {size} the {'largest' if fast else 'smallest'} reference's")
        if envelope.trend is None:
            text += ("; the references do not spread enough to show how their model "
                     "extrapolates: judged by the reference model as calibrated")
        elif envelope.trend.measured:
            text += ("; the reference model follows the references' own trend there, its "
                     "uncertainty and noise widened")
        else:
            text += ("; the references spread too little to measure their trend that far: "
                     "the reference model keeps their outermost values there, its noise "
                     "widened")
    measured = envelope.lines is not None or getattr(envelope, "excite", None) is not None
    t = getattr(states, "t", None)
    return Position(x, distance, name, u, text,
                    None if info is None else np.asarray(info, float),
                    excitation(states) if measured else None,
                    None if t is None else len(t))


#: the growth law of a model error in proportion to the signal it predicts: its residual RMS
#: grows with the channel's excitation, its mean square with the excitation squared, a slope
#: of 2 in log mean square per log excitation (module doc, "The reach")
PROPORTIONAL_SLOPE = 2.0
#: the two-sided 95 % normal quantile: a slope is measured where this many standard errors
#: of it lie within PROPORTIONAL_SLOPE (module doc, "The reach")
REACH_Z = 1.96


@dataclass(frozen=True)
class Reach:
    """A flight beyond what its references can vouch for (module doc, "The reach"):
    ``coordinate`` the envelope coordinate (:data:`COORDINATES` name) along which it lies
    furthest outside the references where they do not measure how their model's lack of fit
    grows, ``excess`` how far (log units), ``above`` whether above their largest (else below
    their smallest), ``spread`` the references' own spread in it (log units); ``slope_se``
    (3,) per coordinate the standard error of that growth's slope (inf: not measurable);
    per residual channel c (C,): ``beyond`` the flight's log excitation beyond the
    references' largest (0 within), ``typical`` the references' typical mean square and
    ``allowance`` the mean square the reference model's own error may add there, both in
    the placed model's sigma_c^2 units (what a weighed flight's ``ms`` is in), ``counts``
    the flight's effective samples N / tau_c (None: N not known): a mean-square reduction
    r on channel c is worth counts_c r / 2 in log evidence. Below the references (module
    doc, "Below the references"): ``under`` (C,) the flight's log excitation under the
    references' smallest (0 within, and 0 on every channel unless the flight lies below
    them along a coordinate whose growth they do not measure) and ``allowance_under`` (C,)
    the mean square, under the typical level, that the reference model's own error may
    leave there for a reading to remove, t_c (1 - exp(-2 under_c)) (sigma_c^2 units)."""

    coordinate: str
    excess: float
    above: bool
    spread: float
    slope_se: np.ndarray
    beyond: np.ndarray
    typical: np.ndarray
    allowance: np.ndarray
    counts: np.ndarray | None = None
    under: np.ndarray | None = None
    allowance_under: np.ndarray | None = None

    @property
    def ratio(self) -> float:
        """``excess`` over ``spread`` (inf where the references do not spread)."""
        return self.excess / self.spread if self.spread > 0 else float("inf")


def slope_errors(x: np.ndarray, log_ms: np.ndarray) -> np.ndarray:
    """(C,) per channel the standard error of the ordinary least-squares slope of the
    references' log mean squares ``log_ms`` (n, C) on ``x`` ((n,) one regressor for every
    channel, or (n, >= C) one per channel, the first C columns): s / sqrt(S_xx,c), s the
    residual spread pooled over the channels (C (n - 2) degrees of freedom); inf below 3
    references or where the regressor does not vary."""
    log_ms = np.asarray(log_ms, float)
    n, c = log_ms.shape
    if n < 3:
        return np.full(c, np.inf)
    x = np.asarray(x, float)
    x = np.repeat(x[:, None], c, axis=1) if x.ndim == 1 else x[:, :c]
    dx = x - x.mean(axis=0)
    s_xx = np.sum(dx ** 2, axis=0)
    slope = np.sum(dx * (log_ms - log_ms.mean(axis=0)), axis=0) / np.where(s_xx > 0, s_xx, 1.0)
    rest = log_ms - log_ms.mean(axis=0) - dx * slope
    spread = np.sqrt(np.sum(rest ** 2) / (c * (n - 2)))
    with np.errstate(divide="ignore"):
        return np.where(s_xx > 0, spread / np.sqrt(s_xx), np.inf)


def reach_of(reference, pos: Position | None, sigma: np.ndarray | None = None
             ) -> Reach | None:
    """The :class:`Reach` of a flight at ``pos`` against the calibrated ``reference`` (module
    doc, "The reach" and "Below the references"); ``sigma`` (C,): the placed model's noise
    scale (default the calibrated one). None where the flight lies outside the references'
    envelope only along coordinates in which they measure their lack of fit's growth (or
    inside it), where it drives no channel beyond the references' largest excitation and
    (below them along such a coordinate) none under their smallest, or where the
    excitations or the references' log mean squares are not kept."""
    envelope = getattr(reference, "envelope", None)
    refs = getattr(envelope, "excite", None)
    log_ms = getattr(reference, "log_ms", None)
    if pos is None or refs is None or pos.excite is None or log_ms is None:
        return None
    c = len(reference.sigma)
    coords = np.asarray(envelope.coords, float)
    if refs.shape[1] < c or len(pos.excite) < c or np.shape(log_ms) != (len(coords), c):
        return None
    se = np.array([slope_errors(coords[:, k], log_ms)[0] for k in range(coords.shape[1])])
    unmeasured = REACH_Z * se > PROPORTIONAL_SLOPE
    above = pos.coords - coords.max(axis=0)
    below = coords.min(axis=0) - pos.coords
    excess = np.where(unmeasured, np.maximum(np.maximum(above, below), 0.0), 0.0)
    beyond = np.maximum(0.0, pos.excite[:c] - refs[:, :c].max(axis=0))
    # under the references' smallest excitation: only where the flight lies below them
    # along a coordinate whose growth they do not measure ("Below the references")
    under = np.maximum(0.0, refs[:, :c].min(axis=0) - pos.excite[:c]) \
        if np.any(unmeasured & (below > 0)) else np.zeros(c)
    if not np.any(excess > 0) or not (np.any(beyond > 0) or np.any(under > 0)):
        return None
    k = int(np.argmax(excess))
    sigma = reference.sigma if sigma is None else np.asarray(sigma, float)
    typical = np.exp(np.asarray(reference.lof_mean, float)) * (reference.sigma / sigma) ** 2
    counts = None if pos.samples is None else pos.samples / np.asarray(reference.tau, float)
    return Reach(COORDINATES[k][0], float(excess[k]), bool(above[k] > 0),
                 float(np.ptp(coords[:, k])), se, beyond,
                 typical, typical * np.expm1(PROPORTIONAL_SLOPE * beyond), counts,
                 under, -typical * np.expm1(-PROPORTIONAL_SLOPE * under))


def local_reference(reference, pos: Position | None):
    """The reference model at a flight's place (module doc): a copy of ``reference`` with its
    shared values at the trend's prediction (held at the outermost reference's where the trend
    is not measured that far or the flight lies beyond the reach: :func:`_predicted_move`),
    and widened scatter, noise scale and lack-of-fit statistics beyond the outermost
    reference, ``place`` = ``pos`` (where the references'
    readings are compared too, :func:`quadsim.gap.calibrate.placed`) and ``reach`` its
    :func:`reach_of` (None within reach); ``reference`` itself where no trend is measured
    and the flight lies within reach."""
    out = _placed_model(reference, pos, reach_of(reference, pos) is not None)
    reach = reach_of(reference, pos, getattr(out, "sigma", None))
    return out if reach is None else dataclasses.replace(out, reach=reach, place=pos)


def _placed_model(reference, pos: Position | None, beyond_reach: bool = False):
    """:func:`local_reference` without the reach; ``beyond_reach``: whether the flight lies
    beyond its references' reach (:func:`reach_of`), where the shared values are not
    extrapolated (:func:`_predicted_move`)."""
    trend = getattr(getattr(reference, "envelope", None), "trend", None)
    pooled = getattr(reference, "lof_pooled", None)
    if pos is not None and pos.distance > 0 and pooled is not None:
        # a channel's own spread holds within the references' envelope; beyond it, at least
        # the pooled one (quadsim.gap.reference)
        reference = dataclasses.replace(
            reference, lof_sd=np.maximum(reference.lof_sd, pooled[0]), lof_dof=pooled[1])
    if pos is None or trend is None or pos.u is None:
        return reference
    # beyond the references' outermost places only: inside, their own statistics hold
    edge = pos.u - np.clip(pos.u, trend.u_low, trend.u_high)
    scatter = reference.scatter
    shift = trend.lof_slope * edge
    widen = np.maximum(shift, 0.0)
    n = len(reference.names) or trend.n
    # per channel: the regression's prediction term, and the trend's own move there (it
    # may bend beyond its references, as for the shared values)
    spread = np.sqrt(reference.lof_sd ** 2
                     + trend.lof_sd ** 2 * edge ** 2 / (trend.s_uu * (1 + 1 / n))
                     + (trend.lof_slope * edge) ** 2)
    # a channel driven beyond every reference expects its line's lack of fit there: in the
    # lack-of-fit statistics only, not in the noise scale (the flight's own effect may be
    # what drives the channel: widening its noise would halve the effect's own precision)
    line = _channel_growth(reference, pos, shift, spread, straight=True)
    shift, spread = _channel_growth(reference, pos, shift, spread)
    # what the straight lines would have expected, where the law expects more (the
    # judgment's "grown" rule: a residual between the two is not sure)
    line = None if np.array_equal(line[0], shift) and np.array_equal(line[1], spread) else \
        (reference.lof_mean + line[0] - widen, line[1])
    lower, upper = getattr(reference, "bounds", None) or parameter_bounds(reference.candidate,
                                                                 reference.params)
    move, var = _predicted_move(trend, pos, edge, beyond_reach or not trend.measured)
    predicted = np.clip(reference.theta + move, lower, upper)
    theta = _physical_towards(reference, predicted, np.sqrt(scatter ** 2 + var))
    # the part of the trend's move that no rigid body can make is the model's error there
    scatter = np.sqrt(scatter ** 2 + var + (predicted - theta) ** 2)
    return dataclasses.replace(
        reference, theta=theta, scatter=scatter, sigma=reference.sigma * np.exp(widen / 2),
        lof_mean=reference.lof_mean + shift - widen, lof_sd=spread, place=pos, lof_line=line)


def _channel_growth(reference, pos: Position, shift, spread, *, straight: bool = False
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The lack-of-fit move ``shift`` (C,) and spread ``spread`` (C,) of
    :func:`local_reference`, on each channel whose excitation the flight drives beyond every
    reference's (:class:`ChannelLines`, module doc) at least the references' own line of
    that channel's lack of fit against its excitation there, read by :func:`growth_law`
    (``straight``: as a straight line): its move (never below the trend's) and its
    prediction spread (never below the spread already there)."""
    lines = getattr(reference.envelope, "lines", None)
    if lines is None or pos.excite is None or len(pos.excite) < len(shift):
        return shift, spread
    out, move, wide = lines.beyond(pos.excite[:len(shift)], straight=straight)
    return (np.where(out, np.maximum(shift, move), shift),
            np.where(out, np.maximum(spread, wide), spread))


def _predicted_move(trend: Trend, pos: Position, edge: float, held: bool = False
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The trend's move of each shared value from the pooled one at the flight's place, and
    its variance (module doc): the place's line, mixed with the inverse-information line by
    the latter's weight where it is measured and the flight's information is known.

    ``edge`` (place units): how far the flight lies beyond the outermost reference. Where
    the references do not measure their model's growth along their axis
    (:attr:`Trend.measured`, references flown alike) the place's line is read at the
    nearest outermost reference instead (move ``b (clip(u) - u_w)``, variance
    ``var(b) (clip(u) - u_w)^2``, no extrapolation term): its slope, measured over a span
    of places many times narrower than the flight's distance, would extrapolate a noise
    slope and free the vehicle's own constants by its variance (module doc, "The reach":
    what the reference model's error may be there is the reach's allowance, not a
    difference of the shared values)."""
    lead = pos.u - trend.u_w
    if held:
        lead, edge = lead - edge, 0.0
    move_u = trend.slope * lead
    var_u = trend.slope_var * lead ** 2 + (trend.slope ** 2 + trend.slope_var) * edge ** 2
    if trend.q_weight is None or pos.info is None or len(pos.info) != len(trend.slope):
        return move_u, var_u
    w = np.where(np.isfinite(pos.info), trend.q_weight, 0.0)
    info = np.where(w > 0, pos.info, trend.q_w)
    lead_q = info - trend.q_w
    edge_q = info - np.clip(info, trend.q_low, trend.q_high)
    move_q = trend.q_slope * lead_q
    var_q = (trend.q_slope_var * lead_q ** 2
             + (trend.q_slope ** 2 + trend.q_slope_var) * edge_q ** 2)
    move = (1.0 - w) * move_u + w * move_q
    return move, (1.0 - w) * var_u + w * var_q + w * (1.0 - w) * (move_u - move_q) ** 2


#: bisection steps of :func:`_physical_towards` (the move kept to 2^-30 of its length)
_PHYSICAL_STEPS = 30


def _physical_towards(reference, theta: np.ndarray, sd: np.ndarray | None = None
                      ) -> np.ndarray:
    """``theta`` where the reference model's vehicle there is physical, else the nearest
    physical point found by taking back the trend's least certain moves first: each moved
    value in turn, in order of its move over its spread ``sd`` (smallest first), goes back
    towards the pooled value ``reference.theta`` (physical: the references were fitted
    there), the last one only as far as the wall (bisection). The trend is a straight line
    fitted on the references, and a rigid body's inertia must keep the triangle inequality
    wherever the line leads (a flat frame's Izz is nearly Ixx + Iyy). The part of the move
    left out widens the shared value's spread (:func:`local_reference`), so the trend's
    artefact is not read as the flight's own difference. The least certain move goes back
    first: it is the one the wall speaks against."""
    if _physical(reference, theta):
        return theta
    base = np.asarray(reference.theta, float)
    theta = np.array(theta, dtype=float)
    moved = np.flatnonzero(theta != base)
    sd = np.ones_like(theta) if sd is None else np.maximum(np.asarray(sd, float), 1e-300)
    for k in moved[np.argsort(np.abs(theta - base)[moved] / sd[moved], kind="stable")]:
        start = theta[k]
        theta[k] = base[k]
        if not _physical(reference, theta):
            continue
        inside, outside = 0.0, 1.0
        for _ in range(_PHYSICAL_STEPS):
            mid = 0.5 * (inside + outside)
            theta[k] = base[k] + mid * (start - base[k])
            if _physical(reference, theta):
                inside = mid
            else:
                outside = mid
        theta[k] = base[k] + inside * (start - base[k])
        return theta
    return theta


def _physical(reference, theta: np.ndarray) -> bool:
    """Whether the shared effects at ``theta`` leave the vehicle physical."""
    from ..core.errors import ModelError
    from ..effects.base import EffectSet

    try:
        EffectSet(tuple(reference.effects(theta))).apply_to_params(reference.params)
    except ModelError:
        return False
    return True
