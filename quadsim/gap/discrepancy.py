"""What the reference flights share and the library lacks: the discrepancy term.

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
  difference extrapolates wildly to a flight flown faster (docs/gap.md, Method);
- moment channels Mx, My, Mz (N m): phi = (v_b, omega, omega_dot): moments of the air speed
  (rotor flapping, the rotors' drag moment), of the body rate (damping) and of the angular
  acceleration (inertia), on any axis (9 features);
- rotor-speed channels: none (their residual is the command -> speed map's, which the
  reference model fits per rotor already).

No constant and no acceleration feature on the force channels: a mass or thrust change is a
steady force and one proportional to the acceleration, and it must stay the flight's own.

``beta_bar_c`` is the mean of each reference flight's least-squares coefficients and
``Sigma_c`` their between-flight covariance times (1 + 1/n) (what a new flight of the same
vehicle may show, n references), with a ridge of :data:`RIDGE` times its diagonal (a
covariance of n flights has rank n - 1 at most). Every explanation's residual is taken
after ``phi beta_bar`` (:func:`centre_term`) and the flight's own ``beta_c - beta_bar_c``
is marginalised with ``Sigma_c`` as extra linear columns of the shared parameters' marginal
(:func:`columns`; :class:`quadsim.gap.problem.Marginal`): an explanation earns evidence
only for what this flight shows beyond what its references already show.

Example::

    >>> d = fit_discrepancy(states_list, params, rotor, effects)
    >>> r = residuals(states, params, effects, rotor_channel=rotor) - centre_term(states, d)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.frames import rotate_inverse

__all__ = [
    "FORCE_FEATURES",
    "MOMENT_FEATURES",
    "RIDGE",
    "Discrepancy",
    "centre_term",
    "columns",
    "features",
    "fit_discrepancy",
]

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

    ``channels`` (tuple of int): the residual channels the term covers (0..5: Fx..Mz);
    ``names[k]``: channel ``channels[k]``'s feature names; ``centre[k]`` (F_k,): the mean
    coefficient beta_bar (channel unit per feature unit: N s/m, N s^2/m^2, N m s/m, N m s,
    N m s^2); ``factor[k]`` (F_k, F_k): a lower-triangular L with L Lᵀ = Sigma_c, the
    coefficients' predictive covariance; ``flights``: how many references it was fitted on;
    ``explained`` (C,): the share of each channel's reference mean square the centre
    explains (0..1; 0 for channels it does not cover)."""

    channels: tuple
    names: tuple
    centre: tuple
    factor: tuple
    flights: int
    explained: np.ndarray
    #: per covered channel, each reference flight's coefficients (n, F_k): what
    #: :meth:`without` leaves one of out
    coefs: tuple = ()

    def without(self, j: int) -> Discrepancy | None:
        """The term fitted on every reference but the ``j``-th (its coefficients left out;
        the channels and explained shares kept): the self-check's leave-one-out reference
        (:mod:`quadsim.gap.selfcheck`). Every channel stays, even where F flights remain
        (the :data:`RIDGE` keeps the covariance positive): the noise model the flight is
        judged with is that of the residual after every channel's centre. None where fewer
        than 2 flights would remain."""
        if not self.coefs or len(self.coefs[0]) - 1 < 2:
            return None
        return _from_coefs(self.channels, self.names,
                           [np.delete(c, j, axis=0) for c in self.coefs], self.explained)

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
    wind is small against the speeds flown)."""
    vb = rotate_inverse(states.quat, states.velocity)
    speed = np.linalg.norm(vb, axis=1)
    out = {}
    for i, axis in enumerate("xyz"):
        out[f"v_{axis}"] = vb[:, i]
        out[f"|v|v_{axis}"] = speed * vb[:, i]
        out[f"w_{axis}"] = states.body_rate[:, i]
        out[f"wd_{axis}"] = states.body_accel[:, i]
    return out


def _design(states, names: tuple, memo: dict | None = None) -> np.ndarray:
    """(N, F) features ``names`` on ``states``, kept in ``memo`` per motion arrays."""
    if memo is None:
        f = features(states)
        return np.column_stack([f[n] for n in names])
    key = ("discrepancy.features", id(states.velocity), id(states.body_accel), names)
    hit = memo.get(key)
    if hit is not None and hit[0] is states.velocity and hit[1] is states.body_accel:
        return hit[2]
    f = features(states)
    x = np.column_stack([f[n] for n in names])
    memo[key] = (states.velocity, states.body_accel, x)
    return x


def channel_features(channel: int) -> tuple:
    """The feature names of residual channel ``channel`` (0..2 forces, 3..5 moments); ()
    for a rotor-speed channel."""
    if channel < 3:
        return tuple(n.replace("#", "xyz"[channel]) for n in FORCE_FEATURES)
    if channel < 6:
        return MOMENT_FEATURES
    return ()


def fit_discrepancy(residual_list, states_list) -> Discrepancy | None:
    """The :class:`Discrepancy` of the reference model's residuals ``residual_list`` (each
    (N_j, C), SI) on the reference ``states_list`` (module doc). A channel with F features
    is covered from F + 1 flights on (below, its coefficients' between-flight covariance is
    not of full rank: the force channels from 5 references, the moments from 10); None
    where no channel is."""
    n = len(states_list)
    if n < 3:
        return None
    chans = residual_list[0].shape[1]
    channels, names, coefs_all = [], [], []
    explained = np.zeros(chans)
    for c in range(min(chans, 6)):
        feats = channel_features(c)
        if n < len(feats) + 1:      # a covariance of F coefficients needs F + 1 flights
            continue
        designs = [_design(s, feats) for s in states_list]
        coefs = np.array([np.linalg.lstsq(x, r[:, c], rcond=None)[0]
                          for x, r in zip(designs, residual_list)])
        channels.append(c)
        names.append(feats)
        coefs_all.append(coefs)
        centre = coefs.mean(axis=0)
        before = sum(float(np.sum(r[:, c] ** 2)) for r in residual_list)
        after = sum(float(np.sum((r[:, c] - x @ centre) ** 2))
                    for x, r in zip(designs, residual_list))
        explained[c] = max(0.0, 1.0 - after / before) if before > 0 else 0.0
    if not channels:
        return None
    return _from_coefs(tuple(channels), tuple(names), coefs_all, explained)


def _from_coefs(channels: tuple, names: tuple, coefs_all: list, explained: np.ndarray
                ) -> Discrepancy:
    """The :class:`Discrepancy` of per-flight coefficients ``coefs_all`` (per channel
    (n, F)): their mean, and their covariance times (1 + 1/n) with the :data:`RIDGE`."""
    centres, factors = [], []
    for coefs in coefs_all:
        n, f = coefs.shape
        cov = np.cov(coefs, rowvar=False).reshape(f, f) * (1.0 + 1.0 / n)
        cov = cov + RIDGE * np.diag(np.diag(cov)) + 1e-30 * np.eye(f)
        centres.append(coefs.mean(axis=0))
        factors.append(np.linalg.cholesky(cov))
    return Discrepancy(channels, names, tuple(centres), tuple(factors), len(coefs_all[0]),
                       explained, tuple(coefs_all))


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
    for c, names, centre in zip(discrepancy.channels, discrepancy.names, discrepancy.centre):
        out[:, c] = _design(states, names, memo) @ centre
    if memo is not None:
        memo[key] = (states.velocity, states.body_accel, discrepancy, out)
    return out


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
    for c, names, factor in zip(discrepancy.channels, discrepancy.names, discrepancy.factor):
        x = _design(states, names, memo) @ factor
        out[:, c, k:k + x.shape[1]] = x * np.sqrt(weights[c])
        k += x.shape[1]
    return out.reshape(n * chans, -1)
