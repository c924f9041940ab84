"""The explanations a flight is weighed by (:mod:`quadsim.gap.evidence`), with their priors.

An *explanation* says how this flight differs from the reference flights
(:class:`quadsim.gap.calibrate.Reference`): a library effect with free parameters and a prior
(centre, spread, source), or a shared parameter group at a value of its own (a motor lag of
its own instead of the references' 7 ms), or a logged signal's delay of its own.
"No difference" has no free parameter of its own. :func:`explanations_for` lists every one
the flight's data can show; :func:`marginal_sd` is the spread of the shared parameters every
explanation carries.

Prior spreads (:func:`prior_spreads`): each effect declares them beside its parameters
(``facts.spreads``, :mod:`quadsim.effects.facts`): one rule -- half the larger end of the
plausible range declared with its source (that range is then about two spreads), centred on
"off" (or on the references' value for a shared group); for the parameters without a range,
the spread's own source is declared with it.

The coupling of a propeller change (:mod:`quadsim.effects.thrust_factor`, and one rotor's in
:mod:`quadsim.effects.thrust_mismatch`): thrust and drag torque per Omega^2 scale together
(same blade, same air; Leishman 2006 ch. 2-3), and the lower load torque lets the motor spin
faster per command, by (1 + change)^-alpha (the effect's module doc: alpha 0.2 for a DC
motor at 75 % voltage efficiency). Alpha is fitted with the prior the references' own
command -> speed map implies (:func:`_alpha_prior`), else N(0.2, 0.1^2) (efficiency 0.6-0.9
for small brushless and brushed motors). A mass moves
neither map nor drag torque, so the command -> speed channel separates the two where commands
are logged.

Example::

    >>> expl = explanations_for(reference, flight.fit)
    >>> [(e.name, e.variant, e.parameter_names) for e in expl][:3]
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..effects.battery_sag import VBAT_SD
from ..effects.body_drag import BodyDrag
from ..effects.canted_rotor import CantedRotor
from ..effects.com_offset import ComOffset
from ..effects.facts import ALL
from ..effects.ground_effect import GroundEffect
from ..effects.mass_offset import MassOffset
from ..effects.scales import arm_length
from ..effects.thrust_curve import ThrustCurve
from ..effects.thrust_factor import ThrustFactor
from ..effects.thrust_mismatch import ThrustMismatch
from ..effects.translational_lift import TranslationalLift
from . import fitting as cable
from .calibrate import SHARED, Reference
from .fitting import DETERMINED, FIT_EFFECTS, WIND_SD_MS
from .logcheck import logged_parts, needs_pose, timing_carried

__all__ = [
    "DELAY_SD_S",
    "DETERMINED",
    "DRAGS",
    "VBAT_SD",
    "Explanation",
    "explanations_for",
    "marginal_sd",
    "own_effects",
    "predictive_delay_sd",
    "prior_of",
    "prior_spreads",
    "reference_delay_sd",
    "reference_determined",
    "vertical_prior",
    "wind_readings",
    "with_wind",
    "TIMING_READINGS",
]

#: the readings of the rotors' timing, not weighed on states judged in a band
#: (:func:`quadsim.gap.logcheck.timing_carried`)
TIMING_READINGS = ("signal_delay", "motor_lag")

# VBAT_SD (re-exported): the prior spread of a full battery voltage, a fraction of the
# pack's voltage (``battery_sag.full_voltage``'s spread, and a flight's V_full against the
# references' mean voltage), declared by :mod:`quadsim.effects.battery_sag`

#: prior spread (s) of a logged signal's delay difference: real logs carry 5-50 ms
#: (:data:`quadsim.logs.delays.MAX_LAG_S` searches 100 ms).
DELAY_SD_S = 0.02


def marginal_sd(reference: Reference, sd: dict | None = None) -> np.ndarray:
    """The spread of the shared parameters in every explanation's prior (module doc): the
    references' ``s_ref``, combined with the physical prior spread of a difference
    (:func:`prior_spreads`) where the parameter has one, by adding precisions:
    ``(s_ref^-2 + w^-2)^-1/2``.

    Why: what a nominal flight may show is never wider than what physics lets a real
    difference be. The references' between-flight scatter of a value their data do not fix
    had no such limit: on the sensor-pipeline testbed (ESC telemetry low-passed, so the
    rotor torque is noisier than the motion) the roll/pitch inertia sat at its bound, +200 %,
    with a scatter of 160 %; the linear marginal then moved it 3 spreads, the model's torque
    vanished, and a 5 mm CoM offset's 13 mN m steady torque was judged "no difference" (83 %).
    With the prior's 50 % the offset is read as 3.9 and 3.6 mm (truth 4.0, 4.8). A parameter
    the references fix (s_ref << w) keeps its spread.

    A parameter whose pooled fit stops at a bound no plausible vehicle has
    (:func:`pinned_at_bound`) gets spread 0: every explanation holds it at the references'
    value. Why: its value there is the bound's, not a measurement, and its between-flight
    scatter is the pull against the bound (on noisy logged rotor speeds the inertia's,
    errors in variables), so the linear marginal, which has no bound, moved it further past
    the bound on every flight: the
    references' inertia at +200 % and a flight's profile +290 % more, the model's torque
    shrunk into the noise, and a CoM offset's or a weak rotor's steady torque with it (the
    campaigns' CoM `unexplained`, a weak rotor named an off-centre mass at 1.00:
    CHANGELOG.md, "The references' inertia at its bound")."""
    sd = prior_spreads(reference.params) if sd is None else sd
    out = np.array(reference.s_ref, dtype=float)
    pinned = pinned_at_bound(reference)
    for k, name in enumerate(reference.candidate.parameter_names):
        w = prior_of(sd, name)
        if name in pinned:
            out[k] = 0.0
        elif w is not None and out[k] > 0:
            out[k] = 1.0 / np.sqrt(out[k] ** -2 + float(w) ** -2)
    return out


def pinned_at_bound(reference: Reference) -> set[str]:
    """The shared parameters whose pooled fit stops at a bound of its range
    (``reference.at_bound``) at a value outside the parameter's plausible range
    (:func:`quadsim.gap.fitting.plausibility`: the inertia at +200 %, where a factor 2 is
    another vehicle): :func:`marginal_sd` holds them. A value at a physical floor (no motor
    lag resolved, no rotor spin inertia, no drag) is a plausible reading of "none" and keeps
    its spread: a flight may show more of it (pinned, the pymulticopter source's calm
    flights' motor lag could not move and their rotor channels read 1.2-1.3x worse)."""
    from .fitting import plausibility

    bound = getattr(reference, "at_bound", None) or {}
    values = reference.values()
    return {name for name in bound
            if name in values and not plausibility(name, values[name], reference.params)[1]}


def prior_of(sd: dict, name: str):
    """The prior spread of parameter ``name`` (``effect.parameter``) in :func:`prior_spreads`'s
    table: its own entry, else its effect's; None without one."""
    return sd.get(name, sd.get(name.split(".")[0]))


def reference_determined(reference: Reference) -> dict[str, bool]:
    """Whether the reference flights determine each shared parameter: identified by their
    fit and a spread ``s_ref`` below :data:`DETERMINED` times its physical prior spread (the
    rule a flight's own values are printed by; a parameter without a prior: identified
    alone). A wind with no drag to act through is the prior's, not theirs."""
    sd = prior_spreads(reference.params)
    out = {}
    for name, s in zip(reference.candidate.parameter_names, reference.s_ref):
        w = prior_of(sd, name)
        out[name] = bool(reference.identified.get(name, True)
                         and (w is None or s < DETERMINED * float(w)))
    return out


def reference_delay_sd(reference: Reference) -> float:
    """How far a nominal flight's rotor delay may lie from the references' (s): the
    predictive spread of one more flight's delay from the references' n estimates,
    ``s_mod sqrt(1 + 1/n)`` (the second term: their mean's own uncertainty), with
    ``s_mod^2 = (s_0^2 + (n - 1) s^2) / n``: their sample variance s^2 (n - 1 degrees of
    freedom) moderated by the estimator's repeatability s_0
    (:data:`quadsim.logs.delays.REPEAT_TOL_S`, 3 ms: the two halves of a log agree to it)
    weighed as one degree of freedom. Each reference's estimate already carries the
    estimator's error, so s holds it once; adding s_0 to s in quadrature counted it twice
    and hid a late rotor log (CHANGELOG.md: Docstrings as contracts). Without references'
    estimates (n = 0): s_0."""
    from ..logs.delays import REPEAT_TOL_S

    _, sd_ms, n = reference.delays_ms.get("rotor", (0.0, 0.0, 0))
    return predictive_delay_sd(1e-3 * sd_ms, n, REPEAT_TOL_S)


def predictive_delay_sd(sd: float, count: int, repeat: float) -> float:
    """:func:`reference_delay_sd`'s formula (s): ``sd`` the references' sample standard
    deviation (s, ddof 1) over ``count`` estimates, ``repeat`` the estimator's
    repeatability (s), weighed as one degree of freedom."""
    if count < 1:
        return float(repeat)
    moderated = (repeat ** 2 + (count - 1) * sd ** 2) / count
    return float(np.sqrt(moderated * (1.0 + 1.0 / count)))


def prior_spreads(params) -> dict:
    """Prior spread per parameter (``effect.parameter``, or ``effect`` for every parameter of
    it; the parameter's unit), for ``params``: each effect's declared ``facts.spreads``
    (module doc)."""
    out = {}
    for name, cls in FIT_EFFECTS.items():
        facts = cls.facts
        for key in facts.spreads:
            out[name if key == ALL else f"{name}.{key}"] = facts.spread_of(key, params)
    return out


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
    #: (parameter, parent) full names: a parameter that acts only through its parent's value
    #: (``Reading.through``; a payload's position through its mass)
    through: tuple = ()
    #: full names of what the reading carries beside its own effect, judged outside their
    #: plausible range only where their 95 % interval lies wholly outside it
    #: (:func:`quadsim.gap.fitting.plausible_values`): a wind's flapping moment, which a
    #: flight that shows little air speed fixes near zero but not in sign
    loose: tuple = ()

    @property
    def parameter_names(self) -> list[str]:
        names = [f"{n}.{p}" for n, _, fitted in self.parts for p in fitted]
        return names + ([f"delay.{self.shift}"] if self.shift else [])

    @property
    def fixed_values(self) -> dict:
        return {f"{n}.{p}": float(v) for n, fixed, _ in self.parts for p, v in fixed.items()}


def _one(name, variant, parts, mean, sd, **kw) -> Explanation:
    return Explanation(name, variant, tuple(parts), tuple(map(float, mean)),
                       tuple(map(float, sd)), **kw)


#: effects whose declared readings (``facts.readings``) come first, in this order (the order
#: the evidence lists and weighs them in); any other effect with readings follows in the
#: registry's order (:func:`reading_effects`)
READING_ORDER = (MassOffset, ComOffset, ThrustCurve, TranslationalLift, GroundEffect, BodyDrag,
                 ThrustFactor, ThrustMismatch, CantedRotor)


def reading_effects() -> list[type]:
    """The effect classes with declared per-flight readings: :data:`READING_ORDER`, then the
    others of :data:`quadsim.gap.fitting.FIT_EFFECTS` in its order."""
    first = {cls.name for cls in READING_ORDER}
    rest = [cls for name, cls in FIT_EFFECTS.items()
            if cls.facts.readings and name not in first]
    return [cls for cls in READING_ORDER if cls.facts.readings] + rest


def _applicable(cls: type, reference: Reference) -> list:
    """``cls``'s readings that the references' logs allow (``Reading.rotor_speeds``)."""
    return [r for r in cls.facts.readings
            if r.rotor_speeds is None or r.rotor_speeds == bool(reference.rotor)]


def _reading(cls: type, reading, sd: dict, alpha: tuple[float, float], *,
             rotor: int | None = None, log_prior: float | None = None) -> Explanation:
    """The explanation of ``reading`` of effect ``cls`` (rotor ``rotor`` of a per-rotor one):
    every parameter centred on "off" with its prior spread, the load exponent on the
    references' (``alpha``: mean, spread, :func:`_alpha_prior`)."""
    name, facts = cls.name, cls.facts
    fitted = tuple(p.format(rotor) for p in reading.fitted) if rotor else reading.fitted
    fixed = {facts.one_per_rotor: float(rotor)} if rotor and facts.one_per_rotor else {}
    fixed.update((p, float(v)) for p, v in reading.fixed)
    exponent = [p == facts.load_exponent for p in fitted]
    if log_prior is None:
        log_prior = -np.log(float(reading.odds)) if reading.odds > 1 else 0.0
    return _one(name, reading.variant.format(rotor) if rotor else reading.variant,
                [(name, fixed, fitted)], [alpha[0] if e else 0.0 for e in exponent],
                [alpha[1] if e else prior_of(sd, f"{name}.{p}") for p, e in zip(fitted, exponent)],
                log_prior=log_prior, coupled=reading.coupled, kin=reading.kin,
                through=tuple((f"{name}.{c}", f"{name}.{q}") for c, q in reading.through))


def explanations_for(reference: Reference, states, names=None) -> list[Explanation]:
    """Every explanation the flight's data can show (``names``: restrict to these effects)."""
    params, sd = reference.params, prior_spreads(reference.params)
    ref = reference.values()
    # the rotor speeds' timing is read by its likelihood wherever they are logged and the
    # references' own timing is fitted (calibrate._refine); the cross-correlation estimate
    # is only a start, which may hold on no reference (CHANGELOG.md: Docstrings as contracts)
    delay = states.rotor_speed is not None and (reference.timing
                                                or "rotor" in reference.delays_ms)
    out = [_one("no_difference", "", (), (), ())]
    groups = {name for name, _, _ in reference.candidate.parts}
    for group, fitted in SHARED:          # a shared group at a value of its own
        if group in ("nominal_refit", "thrust_curve") or group not in groups:
            continue
        keys = [f"{group}.{p}" for p in fitted]
        s_ref = dict(zip(reference.candidate.parameter_names, marginal_sd(reference, sd)))
        spread = [np.hypot(s_ref[k], prior_of(sd, k)) for k in keys]
        if group == "wind":
            out.extend(wind_readings(reference, [ref[k] for k in keys], spread))
            continue
        fixed = next(f for name, f, _ in reference.candidate.parts if name == group)
        out.append(_one(group, "", [(group, dict(fixed), fitted)], [ref[k] for k in keys],
                        spread, replaces=(group,)))
        if group == "motor_lag" and "speed_gain" in groups:
            out[-1] = dataclasses.replace(out[-1], log_prior=-np.log(2.0))
            out.append(_motor_change(reference, ref[keys[0]], spread[0],
                                     np.hypot(s_ref[SPEED_GAIN_KEY], MOTOR_GAIN_SD)))
    # each effect's declared readings (facts.readings): the whole-vehicle ones, then per rotor
    alpha = _alpha_prior(reference, sd)
    for cls in reading_effects():
        out += [_reading(cls, r, sd, alpha) for r in _applicable(cls, reference)
                if not r.per_rotor]
    rotors = params.rotor_count
    for k in range(1, rotors + 1):
        for cls in reading_effects():
            mine = [r for r in _applicable(cls, reference) if r.per_rotor]
            # a form of a reading (fixed values of its own: one rotor's thrust change with its
            # drag torque unchanged) has the prior of the readings, not a share of it
            kinds = max(1, sum(1 for r in mine if not r.fixed))
            out += [_reading(cls, r, sd, alpha, rotor=k, log_prior=-np.log(rotors * kinds))
                    for r in mine]
    # a payload on a cable, its swing driven by the logged motion (quadsim.gap.fitting),
    # alone or with what holds it fixed to the frame (a hook, a mount,
    # the cable's clamp: a mass at the centre; a real hanging payload has one, and without
    # it the swinging mass reads between the two); the variants share the effect's prior
    mean, spread = cable.prior(params)
    out.append(_one("cable_payload", "", [("cable_payload", {}, cable.FITTED)], mean, spread,
                    log_prior=-np.log(2.0)))
    # with its mount the cable hangs from a point of the frame, not the CoM: its height
    # (body z, prior spread half the rotor arm) gives the swing's pull a moment arm
    out.append(_one("cable_payload", CABLE_MOUNT,
                    [("cable_payload", {}, cable.FITTED + ("z",)), ("mass_offset", {}, ("mass",))],
                    mean + [0.0, 0.0], spread + [0.5 * arm_length(params), sd["mass_offset.mass"]],
                    log_prior=-np.log(2.0)))
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
    elif getattr(states, "synthesised", False) and "battery_sag" not in groups:
        # speeds synthesised from the commands (logcheck): a sag beyond the references'
        # map acts on them (fitting.upstream_speeds), read as a rate (the voltage the
        # synthesis read already: the references' map and its voltage law)
        out.append(_one("battery_sag", "", [("battery_sag", {}, ("rate",))], [0.0],
                        [sd["battery_sag.rate"]]))
    if delay:
        out.append(_one("signal_delay", "rotor", (), [0.0],
                        [np.hypot(DELAY_SD_S, reference_delay_sd(reference))], shift="rotor"))
    if "wind" in groups and not wind_measured(reference):
        out = [with_wind(e, reference) if e.name in DRAGS else e for e in out]
    if names is not None:
        keep = set(names) | {"no_difference", "signal_delay"}
        out = [e for e in out if e.name in keep]
    if not getattr(states, "pose", True):       # IMU and motors only (quadsim.gap.logcheck)
        out = [e for e in out if not needs_pose(e.parts, logged_parts(states))]
    if not timing_carried(getattr(states, "window_s", 0.0)):    # judged in a band (logcheck)
        out = [e for e in out if e.name not in TIMING_READINGS]
    if delay:       # the rotor delay as a shared parameter of every other explanation
        tight = reference_delay_sd(reference)
        out = [e if e.shift else dataclasses.replace(e, mean=e.mean + (0.0,),
                                                     sd=e.sd + (tight,), shift="rotor")
               for e in out]
    return out


#: the cable payload's variant with a mass fixed to the frame as well (its mount)
CABLE_MOUNT = "with a part fixed to the frame"
#: the motor-change reading's speed per command (:func:`_motor_change`)
SPEED_GAIN_KEY = "speed_gain.gain"
MOTOR_CHANGE = "another motor or ESC (its time constant and speed per command)"
#: prior spread of that reading's change of the steady speed per command (fraction): a motor
#: of another KV rating, or an ESC with another throttle range. KV ratings within one motor
#: size are sold 1.5-2x apart (e.g. 1400-2700 KV for 22xx motors), and an ESC's throttle
#: endpoints shift the speed per command by as much as they are recalibrated; a quarter is
#: a change a swap makes likely, and half the parameter's range (:mod:`.speed_gain`)
MOTOR_GAIN_SD = 0.25


def _motor_change(reference: Reference, lag: float, lag_sd: float, gain_sd: float
                  ) -> Explanation:
    """Another motor or ESC (:data:`MOTOR_CHANGE`): the time constant and the steady speed
    per command (:mod:`.speed_gain`) both of the flight's own, each centred on the
    references'. A motor's time constant and its speed per volt come from the same
    constants (its torque constant and winding resistance), so a changed motor moves both;
    the plain ``motor_lag`` reading moves only the first. Half the reading's prior each.

    Why: a slower motor can also spin faster per command, and the plain lag reading then
    has no place for the speed's change (CHANGELOG.md: Docstrings as contracts)."""
    ref = reference.values()
    return _one("motor_lag", MOTOR_CHANGE, [("motor_lag", {}, ("time_constant",)),
                                            ("speed_gain", {}, ("gain",))],
                [lag, ref[SPEED_GAIN_KEY]], [lag_sd, gain_sd],
                replaces=("motor_lag", "speed_gain"), log_prior=-np.log(2.0))


#: the least spread of the speed-per-command exponent's prior (:func:`_alpha_prior`): at
#: 0.01 a 10 % propeller change moves the speed per command by 0.1 %, below what one
#: flight's rotor channel resolves, so a tighter prior changes no evidence
ALPHA_MIN_SD = 0.01


def _alpha_prior(reference: Reference, sd: dict) -> tuple[float, float]:
    """(mean, spread) of a propeller reading's speed-per-command exponent alpha: what the
    references' own command -> speed map implies (:attr:`Reference.load_exponent`,
    :func:`quadsim.gap.residual.load_exponent`: 0 for a speed-controlled motor), within the
    effect's range and at least :data:`ALPHA_MIN_SD` wide; where their commands do not say,
    the textbook DC motor N(0.2, 0.1^2) (module doc). Why: with the textbook prior on
    speed-controlled rotors (alpha 0, two spreads from its centre) a propeller change paid log
    units for an exponent the data put at 0 and lost to a mass or a thrust curve that predict
    the same motion (CHANGELOG.md: Docstrings as contracts); against a speed-controlled motor
    the two cannot be told apart by the command -> speed map, and the evidence now says so."""
    implied = getattr(reference, "load_exponent", None)
    if implied is None:
        return 0.2, float(sd["thrust_factor.alpha"])
    return float(np.clip(implied[0], 0.0, 0.5)), max(float(implied[1]), ALPHA_MIN_SD)


#: explanations that give the flight an air-speed load of its own (a drag, a translational
#: lift): where the references do not identify their rotor drag (so their wind is no
#: measured air force), each refits the shared wind with it (:func:`with_wind`). Not where
#: the references' drag is identified: there a body drag with the wind refitted is a superset
#: of the wind reading and takes it. All four, not one: a reading that alone refits the wind
#: takes the others' flights, and each reads the references' leftover wind through its own
#: law (the lift's k_h |v - w|^2 carries -2 k_h v . w; blade flapping's moment
#: k Omega e_z x (v - w), :mod:`quadsim.effects.blade_flapping`), which held fixed leaves
#: its flights unexplained (docs/effects.md, blade_flapping; CHANGELOG.md: Docstrings as contracts).
DRAGS = ("rotor_drag", "body_drag", "translational_lift", "blade_flapping")


def wind_measured(reference: Reference) -> bool:
    """Whether the references' shared wind is one their flights measure: their rotor drag
    and both wind components identified (``reference.identified``, the calibration's
    posterior spread below its prior's). Where not, their wind is whatever the fit left and
    a drag reading refits it (:func:`with_wind`). Why both: a rotor drag identified at 0
    (no drag the wind could act through) leaves the wind unidentified, and a wind held at
    such a value enters a drag law's air speed (the flapping law's: a steady moment) as a
    load no reading of this flight fits (measured: CHANGELOG.md, "A wind the references do
    not measure")."""
    ident = reference.identified
    return all(ident.get(key, True) for key in
               ("rotor_drag.coefficient", "wind.vx", "wind.vy"))


def with_wind(expl: Explanation, reference: Reference) -> Explanation:
    """``expl`` with the references' shared wind refitted under the calibration's own prior
    N(0, (5 m/s)^2) (:data:`quadsim.gap.fitting.WIND_SD_MS`). Why: the
    references see a wind only through their own drag (drag coefficient x air speed); where
    they show no rotor drag their wind is whatever the fit left, and under a drag of the
    flight's own it becomes a spurious steady force (marginalised by the Jacobian at their
    zero drag, it cannot be moved). The references' value means nothing then, so the prior is
    centred on calm air (CHANGELOG.md: Docstrings as contracts). Such a reading is
    ``coupled`` and always fitted to convergence (the screen's linear step cannot move the
    wind)."""
    return dataclasses.replace(expl, parts=expl.parts + (("wind", {}, ("vx", "vy")),),
                               mean=expl.mean + (0.0, 0.0),
                               sd=expl.sd + (WIND_SD_MS, WIND_SD_MS),
                               replaces=expl.replaces + ("wind",), coupled=True)


#: the air-speed moment a wind reading carries with its force (:func:`wind_moment`): the
#: rotors' flapping, roll and pitch (kg m/rad, :mod:`quadsim.effects.blade_flapping`)
WIND_MOMENT = ("blade_flapping", ("roll", "pitch"))


def wind_moment(reference: Reference) -> tuple[list, list, list]:
    """The part a wind reading fits beside its force (``parts``, prior means, prior spreads):
    the rotors' flapping moment (:data:`WIND_MOMENT`), centred on none beyond the
    references' with the effect's prior spread (:func:`prior_spreads`); none (three empty
    lists) where the references' wind is not measured (:func:`wind_measured`): there the
    flapping reading refits the wind itself (:data:`DRAGS`, :func:`with_wind`), the same
    model, and two of it split one name's probability between them.

    Why: a wind acts through every effect of the air speed, the drag force the references'
    drag carries and the hub moment of flapping rotors, which grows with the air speed and
    which the references' own shared values do not hold (:data:`quadsim.gap.calibrate.
    SHARED`): flown in still air at their speeds they show little of it. In a wind the
    moment is of the wind's making; read without it, the flight's pitch moment was left to
    the lack of fit (the tunnel campaign's 1 m/s wind along x: My 35x the references' RMS,
    ``unexplained``) or absorbed by the shared inertia's profile (CHANGELOG.md, "The
    references' inertia at its bound")."""
    name, fitted = WIND_MOMENT
    groups = {part for part, _, _ in reference.candidate.parts}
    if "wind" in groups and not wind_measured(reference):
        return [], [], []
    sd = prior_spreads(reference.params)
    return ([(name, {}, fitted)], [0.0] * len(fitted),
            [float(prior_of(sd, f"{name}.{p}")) for p in fitted])


#: :data:`WIND_MOMENT`'s full parameter names: loose in every wind reading
#: (:attr:`Explanation.loose`)
WIND_MOMENT_KEYS = tuple(f"{WIND_MOMENT[0]}.{p}" for p in WIND_MOMENT[1])


def wind_readings(reference: Reference, mean, spread) -> list[Explanation]:
    """The flight's own wind, through the references' drag as their model has it, and --
    where that drag is a rotor drag (linear in air speed) -- through the same drag as a
    quadratic airframe drag, under either of its two laws (:mod:`quadsim.effects.body_drag`):
    on the air speed, ``|v| v`` (:data:`WIND_DRAG`), or each body axis on its own, ``|v_i|
    v_i`` (:data:`WIND_DRAG_AXES`). C_d A is centred on the references' own equivalent under
    that law (:func:`quadsim.gap.calibrate.quadratic_equivalent`), spread
    :data:`QUADRATIC_SD` of it, the rotor drag replaced; under the law on the air speed the
    references' vertical drag is a parameter of the reading too (:func:`vertical_prior`). The
    plain reading has half the wind's prior, the two quadratic laws a quarter each. Each
    carries the rotors' flapping moment beside the force (:func:`wind_moment`).

    Why: at the references' speeds (about 1 m/s) a linear and a quadratic law give the same
    force; in a wind of several m/s the quadratic law's force grows with the air speed
    squared and its slope with the wind, so a wind read through the linear law leaves the
    force's growth unexplained and misreads the speed. Why both laws: the references' ~1 m/s
    cannot tell them apart, a wind can. In a wind along x the law on the air speed makes the
    sideways drag grow with the wind (``|v| v_y``, 3x at 3 m/s), the law per axis does not
    (``|v_y| v_y``). Fitted where a wind can matter (``kin``: the plain wind reading within
    the screen's cut, or the variant's own screened step,
    :func:`quadsim.gap.screen._kin_matters`), for the per-flight time. Why anchored on the
    references: with C_d A free the variant is a steady force of any size, which takes
    other steady forces (a canted rotor, a rotor drag). The measurements behind each reason:
    CHANGELOG.md ("wind_readings' and vertical_prior's measurements")."""
    flap, flap_mean, flap_sd = wind_moment(reference)
    plain = _one("wind", "", [("wind", {}, ("vx", "vy"))] + flap, list(mean) + flap_mean,
                 list(spread) + flap_sd, replaces=("wind",), log_prior=-np.log(2.0),
                 loose=WIND_MOMENT_KEYS)
    laws = quadratic_laws(reference)
    if not laws:
        return [dataclasses.replace(plain, log_prior=0.0)]
    out = [plain]
    for variant, fixed, drag in laws:
        fitted, centre, sd = ("cd_area",), [drag], [QUADRATIC_SD * drag]
        replaces = ("wind",) + law_replaces(fixed)
        own = vertical_prior(reference, fixed)
        if own is not None:          # the references' vertical drag, refitted at this wind
            fixed = {k: v for k, v in fixed.items() if k != "cd_area_vertical"}
            fitted, centre, sd = fitted + ("cd_area_vertical",), centre + [own[0]], sd + [own[1]]
            replaces = ("wind", "rotor_drag", "body_drag")
        out.append(_one("wind", variant, [("wind", {}, ("vx", "vy")),
                                          ("body_drag", fixed, fitted)] + flap,
                        list(mean) + centre + flap_mean, list(spread) + sd + flap_sd,
                        replaces=replaces, loose=WIND_MOMENT_KEYS,
                        log_prior=-np.log(2.0 * len(laws)), coupled=True, kin=("wind",)))
    return out


#: the references' shared vertical drag (:data:`quadsim.gap.calibrate.BODY_DRAG`)
VERTICAL_KEY = "body_drag.cd_area_vertical"


def vertical_prior(reference: Reference, fixed: dict) -> tuple[float, float] | None:
    """(centre, spread) in m^2 of the vertical C_d A that a wind reading through the law on
    the air speed (``fixed`` without ``per_axis``) carries as a parameter of its own
    (:func:`wind_readings`): the references' shared vertical drag (the same law), their value
    spread by their :func:`marginal_sd` (the pooled standard error with the between-flight
    scatter, and the physical prior). None under the law per body axis (its vertical force
    ``-1/2 rho C_d A_z |v_z| v_z`` does not grow with a horizontal wind: the references'
    equivalent stays fixed, as before), and where the references share no vertical drag or
    it is at 0 (the shared value stands).

    Why a parameter and not the shared value marginalised by its Jacobian at the references'
    place: under the law on the air speed the vertical force ``-1/2 rho C_d A_z |v| v_z``
    grows with the horizontal air speed, so in a wind of several m/s the references' vertical
    drag makes a force their own flights (about 1 m/s) never tested, which the linear
    marginal cannot move: held there, the steady air force's size is fixed and the wind and
    the sideways area trade (measured: CHANGELOG.md, "wind_readings' and vertical_prior's
    measurements"; tests/test_commands_wind.py)."""
    names = list(reference.candidate.parameter_names)
    if fixed.get("per_axis", 0.0) >= 0.5 or VERTICAL_KEY not in names:
        return None
    k = names.index(VERTICAL_KEY)
    value, spread = float(reference.theta[k]), float(marginal_sd(reference)[k])
    return (value, spread) if value > 0 and spread > 0 else None


def quadratic_laws(reference: Reference) -> list[tuple[str, dict, float]]:
    """(variant, fixed values, C_d A in m^2) of the references' drag taken as a quadratic
    airframe drag under each law (:func:`wind_readings`); empty without a rotor drag. The
    law per body axis carries the references' vertical drag too, as its equivalent along
    body z (``cd_area_vertical``, :func:`quadsim.gap.calibrate.vertical_equivalent`): the law
    is the vehicle's, on every axis (:func:`law_replaces`)."""
    axes = {"per_axis": 1.0}
    vertical = getattr(reference, "quadratic_vertical_axes", 0.0)
    if vertical > 0.0:
        axes["cd_area_vertical"] = vertical
    laws = [(WIND_DRAG, {}, reference.quadratic_drag),
            (WIND_DRAG_AXES, axes, reference.quadratic_drag_axes)]
    return [(variant, fixed, drag) for variant, fixed, drag in laws if drag > 0.0]


def law_replaces(fixed: dict) -> tuple[str, ...]:
    """The references' shared groups a quadratic law's fixed values (:func:`quadratic_laws`)
    stand in for: their rotor drag, and their vertical body drag where the law carries its
    equivalent."""
    return ("rotor_drag",) + (("body_drag",) if "cd_area_vertical" in fixed else ())


#: the quadratic-drag wind variants (:func:`wind_readings`): the law on the air speed and
#: the law per body axis
WIND_DRAG = "through the references' drag as a quadratic airframe drag"
WIND_DRAG_AXES = "through the references' drag as a quadratic drag on each body axis"
#: prior spread of that variant's C_d A, as a fraction of the references' equivalent: the
#: equivalence of a linear and a quadratic law depends on the speeds flown (a linear law's
#: equivalent C_d A falls as 1/speed: over the 0.7-1.4 path speeds of the benchmark's
#: references it spans a factor 2, +-35 % about its centre), so half of it
QUADRATIC_SD = 0.5


def own_effects(expl: Explanation, theta: np.ndarray) -> list:
    """The effects of ``expl``'s parts at its values ``theta`` (SI, (P,); a fitted delay
    after them is not read): :func:`quadsim.gap.fitting.built_parts` (the same object for
    the same values)."""
    return cable.built_parts(expl.parts, theta)


