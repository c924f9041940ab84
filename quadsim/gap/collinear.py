"""Collinear explanations in words: each candidate's physical magnitude (:func:`describe`),
what the torque and yaw channels say, and what separates them (:func:`separation`).

Readings the data cannot choose between are all listed in ``verdict.alternatives``
(:mod:`quadsim.gap.diagnose`, from the held-out posterior of
:mod:`quadsim.gap.heldout_verdict`), each with

* ``magnitude``: the fitted parameters as a physical statement with units ("+4.0 ± 0.2 g
  (+10.8 % of the vehicle mass)", "-9.7 ± 0.5 % thrust per Omega^2 on all 4 rotors");
* ``torque_yaw``: the held-out RMS of Mx, My, Mz (N m) that the candidate leaves, so a
  reader sees whether the torque channels prefer one (a thrust-per-Omega^2 change from the
  air also scales the yaw drag torque; an added mass at the CoM leaves torques alone);
* ``separate_by``: the measurement or manoeuvre that would tell them apart;
* ``plausible`` / ``plausibility``: the prior check of :mod:`quadsim.gap.priors` (score
  <= 1 plausible). An implausible candidate is flagged and never named.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from ..vehicle.params import VehicleParams, hover_speed
from .fitmodels import FIT_EFFECTS, effect_class

__all__ = ["SEPARATE", "describe", "separation", "torque_text", "unit_of"]

def _separate() -> dict:
    out: dict = {}
    for name, cls in FIT_EFFECTS.items():
        for other, text in cls.facts.separate_from.items():
            pair = frozenset({name, other})
            if out.get(pair, text) != text:
                raise ValueError(f"{name} and {other}: two texts on what separates them")
            out[pair] = text
    return out


#: known collinear pairs and what data would separate them: a read-only view of the effects'
#: declared ``facts.separate_from`` (each pair declared by one of the two)
SEPARATE = MappingProxyType(_separate())


#: fitted parameters that are not part of an answer (a payload's swing at the first sample).
_NUISANCE = ("cable_payload.lean_", "cable_payload.rate_")


def separation(best: str, others: list[str]) -> dict:
    """What tells reading ``best`` from each of ``others`` (:data:`SEPARATE`; a generic
    advice for a pair without one)."""
    return {other: SEPARATE.get(frozenset({best.split("+")[0], other.split("+")[0]}),
                                "more varied flights (speeds, heights, attitudes)")
            for other in others}


def unit_of(parameter: str) -> str:
    """Unit of ``effect.parameter`` (from the effect's declaration)."""
    name, _, p = parameter.partition(".")
    try:
        specs = {s.name: s for s in effect_class(name).parameters}
    except KeyError:
        return ""
    if p in specs:
        return specs[p].unit
    return "1" if p.startswith("rotor_") else ""


def _num(x: float, digits: str, sign: str = "") -> str:
    """``x`` formatted with ``digits``; a value of 100 up to a million that this would write
    with an exponent ("1e+02") as a whole number instead ("100")."""
    text = f"{x:{sign}{digits}}"
    if "e" in text and 100 <= abs(x) < 1e6:
        text = f"{x:{sign}.0f}"
    return text


def _pm(value: float, ci: float | None, scale: float, digits: str = ".2g") -> str:
    if ci is None or not np.isfinite(ci):
        return _num(value * scale, digits, "+")
    return f"{_num(value * scale, digits, '+')} ± {_num(abs(ci) * scale, digits)}"


def describe(name: str, values: dict, ci: dict, params: VehicleParams,
             fixed: dict | None = None) -> str:
    """Physical statement (with units) of a fitted candidate (``fixed``: the values held
    fixed in the fit, e.g. ``canted_rotor.rotor``)."""
    parts = []
    if "canted_rotor.tilt_x" in values and "canted_rotor.tilt_y" in values:
        parts.append(_canted(values, ci, params, (fixed or {}).get("canted_rotor.rotor")))
    for key, value in values.items():
        if key.startswith("canted_rotor.tilt_") or key.startswith(_NUISANCE):
            continue
        c = ci.get(key)
        if key == "mass_offset.mass":
            parts.append(f"{_pm(value, c, 1e3)} g heavier ({100 * value / params.mass:+.1f} % "
                         f"of the model's {1e3 * params.mass:.4g} g)")
        elif key in ("thrust_factor.change", "nominal_refit.thrust"):
            parts.append(f"{_pm(value, c, 100)} % thrust per Ω² on all {params.rotor_count} "
                         "rotors")
        elif key == "nominal_refit.drag":
            parts.append(f"{_pm(value, c, 100)} % drag torque per Ω²")
        elif key.startswith("thrust_mismatch.rotor_"):
            parts.append(f"{key.split('.')[1]} {_pm(value, c, 100)} % thrust")
        elif key == "thrust_curve.linear":
            hover = hover_speed(params)
            rel = value * hover / (params.thrust_factor * hover ** 2)
            crel = None if c is None else c * hover / (params.thrust_factor * hover ** 2)
            parts.append(f"{_pm(rel, crel, 100)} % thrust at the hover speed "
                         f"({value:.3g} N s/rad per rotor)")
        elif key.startswith("com_offset."):
            parts.append(f"CoM {key[-1]} {_pm(value, c, 1e3)} mm")
        elif key in ("mass_offset.x", "mass_offset.y", "mass_offset.z"):
            parts.append(f"sitting at body {key[-1]} {_pm(value, c, 1e3)} mm")
        else:
            parts.append(_worded(key, value, c, params))
    return ", ".join(parts) if parts else name


def _canted(values: dict, ci: dict, params: VehicleParams, rotor: float | None) -> str:
    """A canted rotor in words: the lean (deg) and its direction, the sideways push at hover."""
    tx, ty = values["canted_rotor.tilt_x"], values["canted_rotor.tilt_y"]
    cx, cy = ci.get("canted_rotor.tilt_x"), ci.get("canted_rotor.tilt_y")
    angle = float(np.hypot(tx, ty))
    c = None if cx is None or cy is None else float(np.hypot(cx, cy))
    push = params.weight / params.rotor_count * np.sin(angle)
    which = f"rotor {int(rotor)}" if rotor is not None else "a rotor"
    lean = _pm(np.degrees(angle), None if c is None else np.degrees(c), 1.0)
    return (f"{which}'s axis leans {lean}"
            f" deg (towards body x {np.degrees(tx):+.2g} deg and y {np.degrees(ty):+.2g} deg): "
            f"it pushes {1e3 * push:.3g} mN sideways at hover ({100 * push / params.weight:.2g} "
            "% of the weight)")


def _worded(key: str, value: float, c: float | None, params: VehicleParams) -> str:
    """Physical statement of one fitted parameter (units named), for the effects that
    :func:`describe` does not word itself; an effect without a wording here is stated with
    its declared description and unit (never as a bare ``effect.parameter = value``)."""
    hover = hover_speed(params)
    weight = params.mass * params.gravity
    r = params.rotor_count
    if key == "battery_sag.full_voltage":
        return (f"the rotors turn slower per command as the battery drops: speed = nominal "
                f"map x vbat / ({_pm(value, c, 1.0, '.3g')} V), i.e. 1 % slower per "
                f"{10 * value:.3g} mV below {value:.3g} V (thrust at a fixed command: 2 % "
                "lower per 1 % of voltage)")
    if key == "battery_sag.rate":
        return (f"the rotors lose {_pm(100 * 60 * value / 2, None if c is None else 100 * 60 * c / 2, 1.0)} "
                f"% speed per minute at a fixed command ({100 * 60 * value:.2g} % thrust per "
                "minute; a discharging battery)")
    if key.startswith("inertia_error."):
        axis = key[-2:]
        i = "xyz".index(axis[0])
        base = params.inertia[i, i]
        return (f"I_{axis} {_pm(value, c, 100)} % ({base * (1 + value):.3g} kg m² instead of "
                f"the model's {base:.3g} kg m²)")
    if key == "ground_effect.gain":
        rise = 100 * (1 / (1 - min(0.5, value / 16)) - 1)
        return (f"ground effect {_pm(value, c, 1.0)} x the Cheeseman–Bennett model "
                f"(+{rise:.2g} % thrust with the rotors one radius above the ground)")
    if key in ("rotor_drag.coefficient", "rotor_drag.axial_coefficient"):
        where = "in the rotor plane" if key.endswith(".coefficient") else "along the rotor axes"
        per = r * value * hover
        cper = None if c is None else r * c * hover
        return (f"rotor drag {where} {_pm(per, cper, 1e3)} mN per m/s of air speed at the "
                f"hover speed ({100 * per / weight:.2g} % of the weight at 1 m/s)")
    if key == "blade_flapping.coefficient":
        moment = r * value * hover                       # N m per m/s of in-plane air speed
        cmoment = None if c is None else r * c * hover
        accel = moment / float(params.inertia[0, 0])
        return (f"blade flapping {_pm(moment, cmoment, 1e3, '.3g')} mN m of nose-up moment per "
                f"m/s of air speed at the hover speed ({accel:.3g} rad/s² of roll/pitch "
                "acceleration at 1 m/s)")
    if key == "translational_lift.k_h":
        lift = r * value * 4.0                           # N at 2 m/s in-plane air speed
        clift = None if c is None else r * c * 4.0
        return (f"translational lift {_pm(lift, clift, 1e3, '.3g')} mN of extra thrust at 2 m/s "
                f"of in-plane air speed ({100 * lift / weight:+.2g} % of the weight; "
                f"k_h {value:.3g} kg/m per rotor)")
    if key in ("body_drag.cd_area", "body_drag.cd_area_vertical"):
        where = "sideways" if key.endswith(".cd_area") else "vertical"
        force = 0.5 * params.air_density * value * 4.0
        return (f"body drag {where} C_d A {_pm(value, c, 1e4)} cm² ({1e3 * force:.2g} mN, "
                f"{100 * force / weight:.2g} % of the weight, at 2 m/s)")
    if key == "motor_lag.time_constant":
        return f"the rotors lag their commands by {_pm(value, c, 1e3)} ms (time constant)"
    if key == "speed_gain.gain":
        return f"the rotors spin {_pm(value, c, 1e2)} % faster per command (steady speed)"
    if key == "gyroscopic.rotor_inertia":
        return f"rotor spin inertia {_pm(value, c, 1e7)} g cm² per rotor (gyroscopic torque)"
    if key.startswith("rate_damping."):
        i = "xyz".index(key[-1])
        tau = params.inertia[i, i] / value if value > 0 else float("inf")
        return (f"{('roll', 'pitch', 'yaw')[i]} rate damping {_pm(value, c, 1.0, '.3g')} "
                f"N m per rad/s (decay time I/k {tau:.3g} s)")
    if key == "cable_payload.mass":
        return (f"a {_pm(value, c, 1e3)} g payload hanging on a cable "
                f"({100 * value / params.mass:+.1f} % of the model's {1e3 * params.mass:.4g} g)")
    if key == "cable_payload.length":
        period = 2 * np.pi * np.sqrt(max(value, 0.0) / params.gravity)
        return (f"cable {_pm(value, c, 1.0, '.2g')} m long (the payload swings with a period "
                f"of about {period:.2g} s)")
    if key.startswith("wind.v"):
        return f"mean wind {_pm(value, c, 1.0)} m/s along world {key[-1]}"
    name, _, p = key.partition(".")
    try:
        spec = {s.name: s for s in effect_class(name).parameters}[p]
        text, unit = spec.doc, spec.unit
    except KeyError:
        text, unit = p.replace("_", " "), unit_of(key)
    return f"{name.replace('_', ' ')}: {text} {_pm(value, c, 1.0, '.4g')} {unit}".rstrip()


def torque_text(entry: dict) -> str:
    rms = entry.get("heldout_rms_after") or {}
    have = [(k, rms[k]) for k in ("Mx", "My", "Mz") if k in rms]
    return ", ".join(f"{k} {v:.2g} N m" for k, v in have)


_torque_text = torque_text  # alias for other modules until integration
