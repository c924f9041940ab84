"""Explanations of one flight against the calibrated reference model, weighed by evidence.

An *explanation* says how this flight differs from the reference flights
(:class:`quadsim.gap.calibrate.Reference`): a library effect with free parameters and a prior
(centre, spread, source), or a shared parameter group at a value of its own (a motor lag of
its own instead of the references' 7 ms), or a logged signal's delay of its own.
"No difference" has no free parameter of its own.

Likelihood (all channels, the references' noise model)::

    -2 log L(theta) = sum_c sum_t r_c(t; theta)^2 / (sigma_c^2 tau_c) + const

(r_c the residual of channel c, sigma_c its RMS and tau_c its correlation time on the
reference flights: N / tau_c effective samples, so a long flight with correlated residuals
does not out-vote physics). The shared parameters theta_s are not fixed: every explanation
carries them with the references' prior N(theta_ref, s_ref^2) (s_ref tempered by the
physical prior of a difference, :func:`marginal_sd`), marginalised in closed form
around theta_ref (linear in theta_s, Jacobian J_s of the weighted residual): with
u = (theta_s - theta_ref) / s_ref, Ĵ = J_s diag(s_ref) and A = I + ĴᵀĴ the profile is
``|r + Ĵ du|^2 + |du|^2`` at ``du = -A^-1 Ĵᵀ r`` and the marginal adds ``-1/2 log det A``.
An explanation that gives a shared group a value of its own takes that group out of the
marginal and fits it with the wider prior N(theta_ref, s_ref^2 + w^2) (w: the prior spread
of a difference, :func:`_prior_sd`). The rotor speeds' logging delay is shared as well, but
not linear at all over a few ms: every explanation fits it, with the references' spread
(:func:`reference_delay_sd`) as its prior; the reading "signal_delay" fits it with the wide
prior N(0, s^2 + (20 ms)^2).

Evidence (Laplace at the bounded least-squares optimum, parameters in units of their prior
spread, z = (theta - mu) / sd)::

    log Z = -1/2 (|aug(z)|^2 + |z|^2) - 1/2 log det H - 1/2 log det A + log pi

with H = JᵀJ of the stacked residual (the posterior precision in z units; -1/2 log det H is
the Occam factor log(posterior volume / prior volume); a value at a bound of its parameter
keeps half the volume, log 2 less) and pi the model prior: equal per
effect, split evenly among an effect's variants (one per rotor for a weak or canted rotor);
"no difference" is weighed against them in :func:`quadsim.gap.judge.posterior`. A parameter is *determined* by the data when its posterior spread is
below half its prior spread (:data:`DETERMINED`); only determined values are ever printed.

Prior spreads (:func:`_prior_sd`): one rule -- half the larger end of the plausible range
documented with its source in :mod:`quadsim.gap.priors` (that range is then about two
spreads), centred on "off" (or on the references' value for a shared group); for the
parameters without a range there, the source is given in the table.

The coupling of a propeller change (:mod:`quadsim.effects.thrust_factor`, and one rotor's in
:mod:`quadsim.effects.thrust_mismatch`): thrust and drag torque per Omega^2 scale together
(same blade, same air; Leishman 2006 ch. 2-3), and the lower load torque lets the motor spin
faster per command, by (1 + change)^-alpha (the effect's module doc: alpha 0.2 for a DC
motor at 75 % voltage efficiency). Alpha is fitted
with prior N(0.2, 0.1^2) (efficiency 0.6-0.9 for small brushless and brushed motors). A mass moves
neither map nor drag torque, so the command -> speed channel separates the two where commands
are logged.

Example::

    >>> rows = evaluate(flight.fit, reference, explanations_for(reference, flight.fit))
    >>> [(e.name, e.log_z) for e in rows]
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve, get_lapack_funcs
from scipy.optimize import least_squares

from ..core.errors import ModelError
from ..effects.battery_sag import nominal_voltage
from ..vehicle.params import hover_speed
from . import cable
from .calibrate import SHARED, Reference, jacobian, shifted
from ..effects import make_effect
from .fitting import (LOCAL_EFFECTS, _area_scale, _arm, _drag_scale, effect_class,
                      min_time_constant, residuals)
from .memo import _memo
from .priors import WIND_SD_MS, momentum_rate_damping, momentum_translational_lift
from .screen import delay_starts, screened

__all__ = ["Explanation", "Evidence", "explanations_for", "evaluate", "marginal_sd",
           "DETERMINED", "DELAY_SD_S", "shifted", "reference_determined"]

#: a parameter is determined when its posterior spread is below this fraction of its prior's.
DETERMINED = 0.5
#: prior spread of a full battery voltage (fraction of the pack's voltage): its charge
#: state, +-10 % (``battery_sag.full_voltage`` in :func:`_prior_sd`, and a flight's V_full
#: against the references' mean voltage)
VBAT_SD = 0.1

#: prior spread (s) of a logged signal's delay difference: real logs carry 5-50 ms
#: (:data:`quadsim.logs.delays.MAX_LAG_S` searches 100 ms).
DELAY_SD_S = 0.02


def marginal_sd(reference: Reference, sd: dict | None = None) -> np.ndarray:
    """The spread of the shared parameters in every explanation's prior (module doc): the
    references' ``s_ref``, combined with the physical prior spread of a difference
    (:func:`_prior_sd`) where the parameter has one, by adding precisions:
    ``(s_ref^-2 + w^-2)^-1/2``.

    Why: what a nominal flight may show is never wider than what physics lets a real
    difference be. The references' between-flight scatter of a value their data do not fix
    had no such limit: on the sensor-pipeline testbed (ESC telemetry low-passed, so the
    rotor torque is noisier than the motion) the roll/pitch inertia sat at its bound, +200 %,
    with a scatter of 160 %; the linear marginal then moved it 3 spreads, the model's torque
    vanished, and a 5 mm CoM offset's 13 mN m steady torque was judged "no difference" (83 %).
    With the prior's 50 % the offset is read as 3.9 and 3.6 mm (truth 4.0, 4.8). A parameter
    the references fix (s_ref << w) keeps its spread."""
    sd = _prior_sd(reference.params) if sd is None else sd
    out = np.array(reference.s_ref, dtype=float)
    for k, name in enumerate(reference.candidate.parameter_names):
        w = _prior_of(sd, name)
        if w is not None and out[k] > 0:
            out[k] = 1.0 / np.sqrt(out[k] ** -2 + float(w) ** -2)
    return out


def _prior_of(sd: dict, name: str):
    """The prior spread of parameter ``name`` (``effect.parameter``) in :func:`_prior_sd`'s
    table: its own entry, else its effect's; None without one."""
    return sd.get(name, sd.get(name.split(".")[0]))


def reference_determined(reference: Reference) -> dict[str, bool]:
    """Whether the reference flights determine each shared parameter: identified by their
    fit and a spread ``s_ref`` below :data:`DETERMINED` times its physical prior spread (the
    rule a flight's own values are printed by; a parameter without a prior: identified
    alone). A wind with no drag to act through is the prior's, not theirs."""
    sd = _prior_sd(reference.params)
    out = {}
    for name, s in zip(reference.candidate.parameter_names, reference.s_ref):
        w = _prior_of(sd, name)
        out[name] = bool(reference.identified.get(name, True)
                         and (w is None or s < DETERMINED * float(w)))
    return out


def reference_delay_sd(reference: Reference) -> float:
    """How far a nominal flight's rotor delay may lie from the references' (s): their
    spread, combined with the estimate's repeatability
    (:data:`quadsim.logs.delays.REPEAT_TOL_S`, 3 ms: the two halves of a log agree to it)."""
    from ..logs.delays import REPEAT_TOL_S

    sd_ms = reference.delays_ms.get("rotor", (0.0, 0.0, 0))[1]
    return float(np.hypot(1e-3 * sd_ms, REPEAT_TOL_S))


def _range_sd(lower: float, upper: float) -> float:
    return 0.5 * max(abs(lower), abs(upper))


def _prior_sd(params) -> dict:
    """Prior spread per parameter (module doc); vehicle-scaled where the range is."""
    arm, mass = _arm(params), params.mass
    hover_thrust = params.thrust_factor * hover_speed(params)   # N per rad/s at hover
    return {
        "mass_offset.mass": _range_sd(-0.05, 0.6) * mass,      # priors: payload to 60 %
        # a payload fixed anywhere within the rotors' span
        "mass_offset.x": _range_sd(-1.0, 1.0) * arm, "mass_offset.y": _range_sd(-1.0, 1.0) * arm,
        "com_offset.x": _range_sd(-0.15, 0.15) * arm, "com_offset.y": _range_sd(-0.15, 0.15) * arm,
        "thrust_mismatch": _range_sd(-0.2, 0.1),
        "thrust_factor.change": _range_sd(-0.15, 0.05),
        # DC-motor efficiency 0.6-0.9 (module doc)
        "thrust_factor.alpha": 0.1,
        "thrust_curve.linear": _range_sd(-0.2, 0.2) * hover_thrust,
        "battery_sag.rate": _range_sd(0.0, 0.005),
        # a battery's full voltage: +-10 % (charge state) of the vehicle's pack
        "battery_sag.full_voltage": VBAT_SD * nominal_voltage(params),
        "inertia_error": _range_sd(-0.5, 1.0),
        "rate_damping": _range_sd(0.0, 3.0) * momentum_rate_damping(params),
        "translational_lift.k_h": _range_sd(0.0, 2.0) * momentum_translational_lift(params),
        "canted_rotor": _range_sd(-0.17, 0.17),
        # Cheeseman & Bennett (1955) ground effect: gain 1 is the textbook curve
        "ground_effect.gain": 1.0,
        # 10 % of the weight at 2 m/s (fitting._drag_scale, _area_scale): a doubled drag
        "rotor_drag": _drag_scale(params),
        "body_drag": _area_scale(params),
        # brushed/brushless micro motors 10-60 ms (Foerster, ETH 2015: Crazyflie 2.0 ~ 15 ms)
        "motor_lag.time_constant": 0.03,
        # rotor+motor inertia: the fit's typical size (fitting.FIT_SPEC)
        "gyroscopic.rotor_inertia": 1e-6 * (mass / 0.04) ** 1.7,
        # indoor drafts to a fresh breeze (Beaufort 3: 3.4-5.4 m/s)
        "wind": WIND_SD_MS,
    }


@dataclass(frozen=True)
class Explanation:
    """How a flight may differ from the references (module doc). ``parts``: (effect, fixed,
    fitted) of its own effects; ``replaces``: shared groups it gives values of its own;
    ``shift``: a signal whose delay it fits ("rotor"); ``log_prior``: log model prior;
    ``coupled``: see the field."""

    name: str
    variant: str
    parts: tuple
    mean: tuple
    sd: tuple
    replaces: tuple = ()
    shift: str | None = None
    log_prior: float = 0.0
    #: True: a parameter acts only through another one's value (a propeller's speed exponent
    #: through its change; a refitted wind through the drag; a payload's position through its
    #: mass), so the screen's linear step at the prior centre cannot see what the explanation
    #: reaches: it is fitted to convergence after the others (:mod:`.screen`)
    coupled: bool = False
    #: for a coupled explanation: the readings it extends or mimics (a payload off the centre:
    #: the centred mass, a CoM shift, a thrust curve; a propeller change: a mass, a thrust
    #: curve). It is fitted when one of them, or its own screened reach, can matter
    #: (:func:`quadsim.gap.screen.screened`); empty: always fitted
    kin: tuple = ()

    @property
    def parameter_names(self) -> list[str]:
        names = [f"{n}.{p}" for n, _, fitted in self.parts for p in fitted]
        return names + ([f"delay.{self.shift}"] if self.shift else [])

    @property
    def fixed_values(self) -> dict:
        return {f"{n}.{p}": float(v) for n, fixed, _ in self.parts for p, v in fixed.items()}


@dataclass
class Evidence:
    """One explanation's result on one flight: MAP values, posterior and prior spreads,
    which values the data determine, log evidence, per-channel mean squared residual over
    sigma_c^2 (``ms``) and the air force of a wind reading (world, N)."""

    explanation: Explanation
    values: dict
    post_sd: dict
    prior_sd: dict
    determined: dict
    log_z: float
    ms: np.ndarray
    mean: np.ndarray | None = None
    air_force: np.ndarray | None = None
    shared_shift: dict = field(default_factory=dict)
    #: True: the linearised evidence of :mod:`.screen` (no full fit: it cannot matter)
    screened: bool = False

    @property
    def name(self) -> str:
        return self.explanation.name


def _one(name, variant, parts, mean, sd, **kw) -> Explanation:
    return Explanation(name, variant, tuple(parts), tuple(map(float, mean)),
                       tuple(map(float, sd)), **kw)


def explanations_for(reference: Reference, states, names=None) -> list[Explanation]:
    """Every explanation the flight's data can show (``names``: restrict to these effects)."""
    params, sd = reference.params, _prior_sd(reference.params)
    ref = reference.values()
    delay = states.rotor_speed is not None and "rotor" in reference.delays_ms
    out = [_one("no_difference", "", (), (), ())]
    groups = {name for name, _, _ in reference.candidate.parts}
    for group, fitted in SHARED:          # a shared group at a value of its own
        if group == "nominal_refit" or group not in groups:
            continue
        keys = [f"{group}.{p}" for p in fitted]
        s_ref = dict(zip(reference.candidate.parameter_names, marginal_sd(reference, sd)))
        spread = [np.hypot(s_ref[k], _prior_of(sd, k)) for k in keys]
        out.append(_one(group, "", [(group, {}, fitted)], [ref[k] for k in keys], spread,
                        replaces=(group,)))
    # a payload at the centre, or off it (its mass and where it sits: it also moves the CoM;
    # the position acts only through the mass, so the fit is coupled); the two variants
    # share the effect's prior
    payload_kin = ("mass_offset", "com_offset", "thrust_curve")
    for variant, fitted in (("", ("mass",)), ("off the centre", ("mass", "x", "y"))):
        keys = [f"mass_offset.{p}" for p in fitted]
        off = len(fitted) > 1
        out.append(_one("mass_offset", variant, [("mass_offset", {}, fitted)],
                        [0.0] * len(keys), [sd[k] for k in keys], log_prior=-np.log(2.0),
                        coupled=off, kin=payload_kin if off else ()))
    one = [("com_offset", ("x", "y")),
           ("thrust_curve", ("linear",)), ("translational_lift", ("k_h",)),
           ("ground_effect", ("gain",)),
           ("body_drag", ("cd_area", "cd_area_vertical"))]
    for name, fitted in one:
        keys = [f"{name}.{p}" for p in fitted]
        out.append(_one(name, "", [(name, {}, fitted)], [0.0] * len(keys),
                        [_prior_of(sd, k) for k in keys]))
    change = ["change", "alpha"] if reference.rotor else ["change"]
    out.append(_one("thrust_factor", "", [("thrust_factor", {}, tuple(change))],
                    [0.0, 0.2][:len(change)],
                    [sd["thrust_factor.change"], sd["thrust_factor.alpha"]][:len(change)],
                    coupled=len(change) > 1, kin=("mass_offset", "thrust_curve")))
    rotors = params.rotor_count
    for k in range(rotors):
        # one propeller: its thrust and drag torque; with commands logged also as a reading
        # of its own in which the rotor's command gives (1 + e)^-alpha of its speed (the
        # motor's load, thrust_factor's alpha). That one is coupled (alpha acts through the
        # deviation); its kin is the plain reading of the same rotor: it is fitted where
        # that one matters (screen._kin_matters). Why two: with alpha in the only reading, a
        # speed-controlled motor (alpha 0, two spreads from the prior's centre) lost its weak
        # rotor to an off-centre mass at 1.00 on the pipeline; without it, a DC motor's weak
        # rotor left its speed channel at 7x the references' (multirotor, `unexplained`)
        variants = [((f"rotor_{k + 1}",), f"rotor {k + 1}")]
        if reference.rotor:
            variants.append(((f"rotor_{k + 1}", "alpha"),
                             f"rotor {k + 1}, with its speed per command"))
        for fitted, variant in variants:
            out.append(_one("thrust_mismatch", variant, [("thrust_mismatch", {}, fitted)],
                            [0.0, 0.2][:len(fitted)],
                            [sd["thrust_mismatch"], sd["thrust_factor.alpha"]][:len(fitted)],
                            log_prior=-np.log(rotors * len(variants)),
                            coupled=len(fitted) > 1,
                            kin=("thrust_mismatch",) if len(fitted) > 1 else ()))
        out.append(_one("canted_rotor", f"rotor {k + 1}",
                        [("canted_rotor", {"rotor": float(k + 1)}, ("tilt_x", "tilt_y"))],
                        [0.0, 0.0], [sd["canted_rotor"]] * 2, log_prior=-np.log(rotors)))
    # a payload on a cable, its swing driven by the logged motion (quadsim.gap.cable)
    out.append(_one("cable_payload", "", [("cable_payload", {}, cable.FITTED)],
                    *cable.prior(params)))
    if reference.rotor and "battery_sag" not in groups:
        volts = getattr(states, "vbat", None)
        if reference.vbat_ref and volts is not None and np.all(np.isfinite(volts)):
            # the speed per command follows this flight's voltage (vbat / V_full), a law
            # the references' steady voltage did not test (calibrate.VBAT_TESTED); V_full
            # about their voltage, +-10 % (charge state, as battery_sag.full_voltage)
            out.append(_one("battery_sag", "", [("battery_sag", {}, ("full_voltage",))],
                            [reference.vbat_ref], [VBAT_SD * reference.vbat_ref]))
        else:                                               # no voltage log: a sag rate
            out.append(_one("battery_sag", "", [("battery_sag", {}, ("rate",))], [0.0],
                            [sd["battery_sag.rate"]]))
    if delay:
        out.append(_one("signal_delay", "rotor", (), [0.0],
                        [np.hypot(DELAY_SD_S, reference_delay_sd(reference))], shift="rotor"))
    if "wind" in groups and not reference.identified.get("rotor_drag.coefficient", True):
        out = [_with_wind(e, reference) if e.name in DRAGS else e for e in out]
    if names is not None:
        keep = set(names) | {"no_difference", "signal_delay"}
        out = [e for e in out if e.name in keep]
    if delay:       # the rotor delay as a shared parameter of every other explanation
        tight = reference_delay_sd(reference)
        out = [e if e.shift else dataclasses.replace(e, mean=e.mean + (0.0,),
                                                     sd=e.sd + (tight,), shift="rotor")
               for e in out]
    return out


#: explanations that give the flight an air-speed load of its own (a drag, a translational
#: lift): where the references do not identify their rotor drag (so their wind is no
#: measured air force), each refits the shared wind with it (:func:`_with_wind`). Not where
#: the references' drag is identified: on Crazyflow and PyFlyt wind flights (their wind not
#: the library's form) a body drag with the wind refitted is a superset of the wind reading
#: and took it at 100 %. Both drags, not one: with only the rotor drag refitting the wind, it
#: took RotorPy's body-drag flights. The lift too: against RotorPy's references' leftover
#: 0.15 m/s wind a lift of the right size (0.0140 against 0.0141 kg/m) left 11x the
#: references' Fz mean square (k_h |v - w|^2 carries -2 k_h v . w) and lost to a thrust
#: curve by 173 log units; with the wind refitted (to 0.001 m/s) it left their level and won
#: by 9.
DRAGS = ("rotor_drag", "body_drag", "translational_lift")


def _with_wind(expl: Explanation, reference: Reference) -> Explanation:
    """``expl`` with the references' shared wind refitted under the calibration's own prior
    N(0, (5 m/s)^2) (:data:`quadsim.gap.priors.WIND_SD_MS`). Why: the
    references see a wind only through their own drag (drag coefficient x air speed); where
    they show no rotor drag their wind is whatever the fit left, and under a drag of the
    flight's own it becomes a spurious steady force (marginalised by the Jacobian at their
    zero drag, it cannot be moved). The references' value means nothing then (3 synthetic
    references without drag in a 1.5 m/s wind left it at 5.6 m/s), so the prior is centred
    on calm air. Such a reading is ``coupled`` and always fitted to convergence (the screen's
    linear step cannot move the wind). Measured on RotorPy references flown without rotor
    drag: their wind sat at 0.6 m/s (set through a vertical drag of 1 cm^2), and a flight with
    rotor drag 15 mN/(m/s) was read as 8.4 with Fx at 36x the references' RMS."""
    return dataclasses.replace(expl, parts=expl.parts + (("wind", {}, ("vx", "vy")),),
                               mean=expl.mean + (0.0, 0.0),
                               sd=expl.sd + (WIND_SD_MS, WIND_SD_MS),
                               replaces=expl.replaces + ("wind",), coupled=True)


def _make(name: str, values: dict):
    if name in LOCAL_EFFECTS:
        return LOCAL_EFFECTS[name](**values)
    return make_effect(name, **values)


def _own_effects(expl: Explanation, theta: np.ndarray) -> list:
    out, k = [], 0
    for name, fixed, fitted in expl.parts:
        values = dict(fixed)
        for p in fitted:
            values[p] = float(theta[k])
            k += 1
        out.append(_make(name, values))
    return out


class _Marginal:
    """The shared parameters not fitted by an explanation, marginalised linearly (module doc)."""

    def __init__(self, jac: np.ndarray, s_ref: np.ndarray):
        self.j = jac * s_ref
        a = np.eye(len(s_ref)) + self.j.T @ self.j
        self.chol = cho_factor(a)
        self.logdet = 2.0 * float(np.sum(np.log(np.diag(self.chol[0]))))
        # cho_solve's own LAPACK call (the same numbers), without its per-call checks and
        # batch wrapper: most of its cost on these small systems, called thousands of times
        self._potrs = get_lapack_funcs(("potrs",), (self.chol[0],))[0] if len(s_ref) else None

    def profile(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rhs = self.j.T @ r
        if self._potrs is None:
            du = -cho_solve(self.chol, rhs)
        else:
            x, info = self._potrs(self.chol[0], rhs, lower=self.chol[1])
            if info != 0:
                raise ValueError(f"illegal value in {-info}th argument of internal potrs")
            du = -x
        return r + self.j @ du, du


def _bounds(expl: Explanation, reference: Reference, dt: float):
    lower, upper = [], []
    for name, _, fitted in expl.parts:
        cls = effect_class(name)
        specs = {p.name: p for p in cls.parameters}
        for p in fitted:
            lo, hi = specs[p].lower, specs[p].upper
            if name == "motor_lag":
                lo = max(lo, min_time_constant(dt))
            if name == "mass_offset" and p == "mass":
                lo, hi = max(lo, -0.5 * reference.params.mass), min(hi, 2 * reference.params.mass)
            elif name == "mass_offset":         # a payload within the rotors' span
                lo, hi = max(lo, -_arm(reference.params)), min(hi, _arm(reference.params))
            if name == "com_offset":
                arm = _arm(reference.params)
                lo, hi = max(lo, -0.5 * arm), min(hi, 0.5 * arm)
            lower.append(lo)
            upper.append(hi)
    if expl.shift:
        lower.append(-0.1)
        upper.append(0.1)
    return np.asarray(lower, float), np.asarray(upper, float)


def _shared_effects(reference: Reference, replaces: tuple) -> tuple[list, list[int]]:
    """The reference effects without the replaced groups, and the marginalised columns."""
    names = reference.candidate.parameter_names
    keep = [k for k, n in enumerate(names) if n.split(".")[0] not in replaces]
    everything, n_base = reference.effects(), len(reference.candidate.base)
    # effects already in the model (held-out mode's --effects-file) stay; an explanation
    # replaces only the fitted shared groups
    effects = everything[:n_base] + [e for e in everything[n_base:] if e.name not in replaces]
    return effects, keep


def _air_force(states, reference, effects, own) -> np.ndarray:
    """Mean air force (world, N) of the flight's wind beyond the references' wind."""
    from ..core.frames import rotate
    from .residual import model_wrench

    base = [e for e in reference.effects() if e.name == "wind"]   # the references' own
    with_wind, _, _ = model_wrench(states, reference.params, effects + own)
    without, _, _ = model_wrench(states, reference.params, effects + base)
    return np.mean(rotate(states.quat, with_wind - without), axis=0)


def evaluate(states, reference: Reference, explanations: list[Explanation],
             start_delay_s: float = 0.0, *, full: bool = False) -> list[Evidence]:
    """Log evidence of every explanation on one flight's (decimated) ``states``.

    With a rotor-delay reading, every explanation fits the flight's rotor delay too: with
    the references' prior (:func:`reference_delay_sd`) as a shared parameter, or with the
    wide prior as the reading "signal_delay". Both start at the best point of a grid of
    delays under their prior (:func:`quadsim.gap.screen.delay_starts`; ``start_delay_s``,
    the cross-correlation estimate against the references', is one of its points).

    Each explanation is first screened by one Gauss-Newton step and fully fitted only where
    it can matter (:mod:`quadsim.gap.screen`); ``full=True`` fits every one."""
    names = list(reference.candidate.parameter_names)
    s_all = marginal_sd(reference)
    memo: dict = {}         # residual parts shared by the evaluations on this flight
    jac = jacobian(states, reference, list(range(len(names))), reference.candidate.effects,
                   memo=memo)
    starts = (0.0, start_delay_s)
    null = next((e for e in explanations if e.name == "no_difference" and e.shift), None)
    wide = next((e for e in explanations if e.name == "signal_delay"), None)
    if null is not None:
        starts = delay_starts(Problem(states, reference, null, jac, s_all, memo),
                              float(wide.sd[-1]) if wide is not None else 0.0, start_delay_s)
    if not full:
        return screened(states, reference, explanations, jac, names, s_all,
                        starts, problem=Problem, fit_one=_fit_one,
                        residual=flight_residual, memo=memo)
    return [_fit_one(states, reference, e, jac, s_all, names,
                     starts[1] if e.name == "signal_delay" else starts[0])
            for e in explanations]


def flight_residual(states, reference: Reference, effects: list, memo: dict | None = None
                    ) -> np.ndarray:
    """:func:`quadsim.gap.calibrate.weighted_residual`, flattened (N C,), with the residual
    parts that repeat on one flight kept in ``memo`` (:func:`quadsim.gap.fitting.residuals`)."""
    r = residuals(states, reference.params, effects, rotor_channel=reference.rotor, memo=memo)
    return (r * np.sqrt(reference.weights)).ravel()


class Problem:
    """One explanation's fit on one flight (module doc): ``residual(z)`` the weighted
    residual (N C,) at z (prior units), ``stacked(z)`` the vector whose squared norm is the
    fit's cost (profiled residual, marginalised shared shifts, z); ``z_lo``, ``z_hi`` the
    bounds; ``shared``/``keep``/``marg`` the reference effects it keeps and their marginal."""

    def __init__(self, states, reference: Reference, expl: Explanation, jac: np.ndarray,
                 s_all: np.ndarray, memo: dict | None = None):
        self.states, self.reference, self.expl = states, reference, expl
        self.memo = memo          # residual parts shared by evaluations on one flight
        if memo is None:
            self.shared, self.keep = _shared_effects(reference, expl.replaces)
        else:       # the same for every explanation that replaces the same groups
            kept = memo.setdefault("shared_effects", {})
            if expl.replaces not in kept:
                kept[expl.replaces] = _shared_effects(reference, expl.replaces)
            self.shared, self.keep = kept[expl.replaces]
        self.marg = self._marginal(jac, s_all)
        self.mean, self.sd = np.asarray(expl.mean), np.asarray(expl.sd)
        lower, upper = _bounds(expl, reference, float(states.t[1] - states.t[0]))
        self.lower, self.upper = lower, upper
        self.z_lo, self.z_hi = (lower - self.mean) / self.sd, (upper - self.mean) / self.sd
        self.size = jac.shape[0] + len(self.keep) + len(self.mean)

    def _marginal(self, jac: np.ndarray, s_all: np.ndarray) -> _Marginal:
        """The marginal of the kept shared columns; with a ``memo``, one per set of columns
        (most explanations keep them all) and Jacobian."""
        if self.memo is None:
            return _Marginal(jac[:, self.keep], s_all[self.keep])
        kept = self.memo.setdefault("marginals", {})
        key = (id(jac), tuple(self.keep), s_all[self.keep].tobytes())
        if key not in kept or kept[key][0] is not jac:
            kept[key] = (jac, _Marginal(jac[:, self.keep], s_all[self.keep]))
        return kept[key][1]

    def residual(self, z: np.ndarray) -> np.ndarray:
        """The weighted residual at ``z``; with a ``memo``, the last one per explanation is
        kept (the screen's step and the refined fit ask again for the point they just
        evaluated: the start of the next step, the step just accepted)."""
        last = None if self.memo is None else self.memo.setdefault("last_residual", {})
        key = (self.expl.name, self.expl.variant)
        if last is not None and key in last and np.array_equal(last[key][0], z):
            return last[key][1]
        # z at its bound gives theta a round-off beyond the parameter's range: clipped
        theta = np.clip(self.mean + self.sd * z, self.lower, self.upper)
        own = _own_effects(self.expl, theta)
        flight = self.shifted(float(theta[-1])) if self.expl.shift else self.states
        r = flight_residual(flight, self.reference, self.shared + own, self.memo)
        if last is not None:
            last[key] = (np.array(z, dtype=float), r)
        return r

    def shifted(self, delay_s: float):
        """:func:`shifted` states, the same object for the same delay (``memo``)."""
        if self.memo is None:
            return shifted(self.states, delay_s)
        return _memo(self.memo, ("shifted", id(self.states), delay_s), self.states,
                     lambda: shifted(self.states, delay_s))

    def stacked(self, z: np.ndarray) -> np.ndarray:
        try:
            r = self.residual(z)
        except ModelError:
            return np.full(self.size, 1e3)
        aug, du = self.marg.profile(r)
        return np.concatenate([aug, du, z])

    def start(self, start_delay_s: float = 0.0) -> np.ndarray:
        """z = 0 with the delay at ``start_delay_s``, inside the bounds."""
        z0 = np.zeros_like(self.mean)
        if self.expl.shift:
            z0[-1] = start_delay_s / self.sd[-1]
        return np.clip(z0, self.z_lo + 1e-6, self.z_hi - 1e-6)

    def evidence(self, z, vec, h, at_bound: int, names_all, s_all) -> Evidence:
        return laplace(self.states, self.reference, self.expl, self.marg, self.keep, s_all,
                       names_all, self.shared, z, vec, h, at_bound)


def _fit_one(states, reference: Reference, expl: Explanation, jac: np.ndarray,
             s_all: np.ndarray, names_all: list[str], start_delay_s: float,
             start: np.ndarray | None = None) -> Evidence:
    """One explanation's MAP fit and Laplace evidence (module doc); ``jac`` (N C, M): the
    weighted residual's Jacobian in the shared parameters ``names_all`` (spreads ``s_all``),
    of which those the explanation does not replace are marginalised. ``start``: where the
    fit starts (z units; default :meth:`Problem.start`)."""
    prob = Problem(states, reference, expl, jac, s_all)
    if not len(prob.mean):
        return prob.evidence(np.zeros(0), prob.stacked(np.zeros(0)), np.zeros((0, 0)), 0,
                             names_all, s_all)
    z0 = prob.start(start_delay_s) if start is None else np.clip(
        np.asarray(start, dtype=float), prob.z_lo + 1e-6, prob.z_hi - 1e-6)
    fit = least_squares(prob.stacked, z0, bounds=(prob.z_lo, prob.z_hi), diff_step=1e-3,
                        max_nfev=40, method="trf")
    return prob.evidence(fit.x, fit.fun, fit.jac.T @ fit.jac,
                         int(np.count_nonzero(fit.active_mask)), names_all, s_all)


def laplace(states, reference: Reference, expl: Explanation, marg: _Marginal, keep: list[int],
            s_all: np.ndarray, names_all: list[str], shared: list, z: np.ndarray,
            vec: np.ndarray, h: np.ndarray, at_bound: int) -> Evidence:
    """The Evidence of ``expl`` at ``z`` (module doc): ``vec`` the stacked residual there,
    ``h`` the posterior precision (z units), ``at_bound`` how many values lie at a bound."""
    chans = len(reference.sigma)
    mean, sd = np.asarray(expl.mean), np.asarray(expl.sd)
    if len(mean):
        # a value at a bound: the posterior there is half a Gaussian, half the Laplace volume
        logdet_h = np.linalg.slogdet(h)[1] + 2.0 * np.log(2.0) * at_bound
        post = sd * np.sqrt(np.clip(np.diag(np.linalg.pinv(h)), 0, None))
    else:
        logdet_h, post = 0.0, np.zeros(0)
    theta = mean + sd * z
    log_z = -0.5 * float(vec @ vec) - 0.5 * logdet_h - 0.5 * marg.logdet + expl.log_prior
    n = marg.j.shape[0]
    resid = vec[:n].reshape(-1, chans) * np.sqrt(reference.tau)
    keys = expl.parameter_names
    shift = {names_all[k]: float(s_all[k] * d) for k, d in zip(keep, vec[n:n + len(keep)])}
    own = [expl.name == "signal_delay" or k != "delay.rotor" for k in keys]
    ev = Evidence(expl, dict(zip(keys, map(float, theta))), dict(zip(keys, map(float, post))),
                  dict(zip(keys, map(float, sd))),
                  {k: bool(p < DETERMINED * q) for k, p, q, o in zip(keys, post, sd, own) if o},
                  log_z, np.mean(resid ** 2, axis=0), np.mean(resid, axis=0) * reference.sigma,
                  shared_shift=shift)
    if expl.name == "wind":
        lower, upper = _bounds(expl, reference, float(states.t[1] - states.t[0]))
        ev.air_force = _air_force(states, reference, shared,
                                  _own_effects(expl, np.clip(theta, lower, upper)))
    return ev
