"""Plausible magnitudes of fitted effects, with sources: what ranks collinear explanations.

When two candidates explain the same forces (an added mass and a uniform loss of thrust per
Omega^2 are the same in the force balance up to drag), the data cannot choose; physics can
say which magnitude is believable. Each prior is a range of the *relative* or absolute size
that real vehicles show; a fit outside it is flagged ``implausible`` and never named.

=====================  ===================  ==============================================
parameter              plausible range      source / reasoning
=====================  ===================  ==============================================
thrust_factor.change   -15 % .. +5 %        props of one type differ by a few % in b
                                            (UIUC propeller database, Brandt & Selig,
                                            AIAA 2011-1255: C_T spread 2-5 % between
                                            samples); air density 1.225 -> 1.06 kg/m^3 from
                                            sea level to 1500 m or +-5 % over 0-30 C (ISA);
                                            wear/chips lose a few %. Together: -15 .. +5 %.
nominal_refit.thrust   -15 % .. +5 %        same as thrust_factor (a refit of b).
mass_offset.mass       -5 % .. +60 % of m   payload: nano quads carry up to ~50-60 % of
                                            their mass (Crazyflie 2.1: 37 g, payload limit
                                            15 g, Bitcraze datasheet); a lighter vehicle
                                            than the model by more than a battery-to-battery
                                            spread (~5 %) is unlikely.
thrust_mismatch.*      -20 % .. +10 %       one damaged/mismatched prop or motor.
com_offset.x/y         within 15 % of arm   battery/payload placement.
thrust_curve.linear    +-20 % at hover      bench fits: linear term up to ~20 % (Foerster 2015).
battery_sag.rate       0 .. 0.5 %/s         a 1S LiPo loses ~20 % thrust at a fixed
                                            command over a 5-7 min flight (0.05-0.1 %/s);
                                            0.5 %/s is a failing cell.
inertia_error.*        -50 % .. +100 %      a CAD or lumped-mass inertia is within ~10-20 %
                                            (this project: CAD vs SolidWorks +9 %; the
                                            Crazyflie literature spread is +-20 %); a factor
                                            2 either way means a different vehicle.
rate_damping.*         0 .. 3 k_mt          momentum theory: a rolling vehicle's rotor discs
                                            see +-r w of inflow, dT/dv = T / (2 v_i) per
                                            rotor, so k_mt = r^2 T_h / v_i (r the arm, T_h the
                                            hover thrust per rotor, v_i = sqrt(T_h / (2 rho
                                            A)); Bristeau et al., ECC 2009, sec. 4); blade
                                            flapping and frame drag add moments of the same
                                            order (Mahony, Kumar & Corke, IEEE RAM 2012).
                                            k_mt: 0.020 N m s/rad (0.84 kg testbed), 5.8e-5
                                            (Crazyflie); decay times I/k below ~0.1 s are
                                            not aerodynamic damping.
canted_rotor.tilt_*    -10 .. +10 deg       a bent mount or crash-bent arm leans a rotor a
                                            few degrees; more is a visibly broken arm.
translational_lift.k_h 0 .. 2 k_tl          momentum theory: at a fixed rotor speed an edgewise
                                            speed V lowers the induced inflow v_i = v_h^2 /
                                            sqrt(V^2 + v_i^2) (Glauert) by V^2 / (4 v_h^2), and
                                            blade-element theory turns that into dT/T ~ sigma a
                                            / (8 lambda_h) V^2 / (4 v_h^2), the first factor
                                            0.5-2 for small propellers (Leishman 2006, eqs.
                                            2.122, 3.93): k_tl = T_h / (4 v_h^2) per rotor.
                                            k_tl = rho pi R_p^2 / 2: 0.031 kg/m (0.84 kg
                                            testbed, R_p 127 mm), 1.5e-3 (Crazyflie model,
                                            27.5 mm; RotorPy's Crazyflie-brushless k_h:
                                            1.11e-3).
wind.vx/vy             sd 5 m/s (Gaussian)  indoor drafts to a fresh breeze (Beaufort 3:
                                            3.4-5.4 m/s); :data:`WIND_SD_MS`, the spread of
                                            the per-flight wind reading and the prior of the
                                            reference calibration's shared wind.
=====================  ===================  ==============================================

:func:`plausibility` returns (score, plausible, text): score = |value| / bound on its side
(<= 1 plausible; the smaller, the more plausible).
"""

from __future__ import annotations

import math

from ..vehicle.params import VehicleParams

__all__ = ["PRIORS", "plausibility", "candidate_plausibility", "momentum_rate_damping",
           "momentum_translational_lift"]

#: parameter -> (lower, upper, kind, source). kind "relative": fraction of 1; "mass": of the
#: vehicle mass; "arm": of the arm length; "absolute": in the parameter's unit.
#: prior spread of a steady wind, m/s (indoor drafts to Beaufort 3, 3.4-5.4 m/s)
WIND_SD_MS = 5.0

PRIORS = {
    "thrust_factor.change": (-0.15, 0.05, "relative",
                             "prop-to-prop C_T spread 2-5 % (UIUC prop data), air density "
                             "+-5 % (0-30 C) or -13 % at 1500 m (ISA), wear"),
    "nominal_refit.thrust": (-0.15, 0.05, "relative", "as thrust_factor.change"),
    "mass_offset.mass": (-0.05, 0.6, "mass",
                         "payloads up to ~60 % of the vehicle mass (Crazyflie 2.1: 15 g on "
                         "37 g, Bitcraze); lighter than modelled by > 5 % is unlikely"),
    "thrust_mismatch": (-0.2, 0.1, "relative", "one damaged or mismatched prop/motor"),
    "com_offset.x": (-0.15, 0.15, "arm", "battery/payload placement"),
    "com_offset.y": (-0.15, 0.15, "arm", "battery/payload placement"),
    "battery_sag.rate": (0.0, 0.005, "absolute", "1S LiPo: ~20 % thrust over a 5-7 min flight"),
    "inertia_error": (-0.5, 1.0, "relative",
                      "CAD/lumped inertia within 10-20 % (CAD vs SolidWorks +9 %, Crazyflie "
                      "literature +-20 %); a factor 2 is another vehicle"),
    "rate_damping": (0.0, 3.0, "momentum",
                     "momentum theory k = r^2 T_hover / v_i (Bristeau et al. 2009) x 3 for "
                     "blade flapping and frame drag (Mahony et al. 2012)"),
    "canted_rotor": (-0.17, 0.17, "absolute",
                     "a bent motor mount or arm leans a rotor a few deg; more than 10 deg "
                     "(0.17 rad) is a visibly broken arm"),
    "translational_lift.k_h": (0.0, 2.0, "lift",
                               "momentum theory k = T_hover / (4 v_i^2) per rotor (Glauert "
                               "inflow, Leishman 2006) x 2 for the blade-element factor"),
    "thrust_curve.linear": (-0.2, 0.2, "hover",
                            "bench fits T = k2 W^2 + k1 W + k0 (Foerster, ETH 2015, table "
                            "3.3): the linear term reaches ~20 % of the hover thrust"),
}

#: score given to a parameter without a prior (ranks between well inside and at the edge).
NO_PRIOR_SCORE = 0.5


def _key(parameter: str) -> str | None:
    if parameter in PRIORS:
        return parameter
    head = parameter.split(".")[0]
    return head if head in PRIORS else None


def plausibility(parameter: str, value: float, params: VehicleParams):
    """(score, plausible, prior text) of a fitted ``value``; (0, True, "") without a prior."""
    key = _key(parameter)
    if key is None:
        return NO_PRIOR_SCORE, True, ""
    lower, upper, kind, source = PRIORS[key]
    if kind == "mass":
        value = value / params.mass
    elif kind == "hover":  # linear thrust term as a fraction of the hover thrust
        value = value / hover_thrust_per_speed(params)
    elif kind == "arm":
        import numpy as np

        value = value / float(np.max(np.linalg.norm(params.rotor_positions[:, :2], axis=1)))
    elif kind == "momentum":
        value = value / momentum_rate_damping(params)
    elif kind == "lift":
        value = value / momentum_translational_lift(params)
    bound = upper if value >= 0 else lower
    score = abs(value) / abs(bound) if bound != 0 else (0.0 if value == 0 else float("inf"))
    scale = {"relative": 100, "mass": 100, "arm": 100, "hover": 100, "absolute": 1,
             "momentum": 1, "lift": 1}[kind]
    unit = {"relative": " %", "mass": " % of the vehicle mass", "arm": " % of the arm",
            "hover": " % of the hover thrust", "absolute": "",
            "momentum": (f" x the momentum-theory damping "
                         f"{momentum_rate_damping(params):.2g} N m s/rad"),
            "lift": (f" x the momentum-theory lift "
                     f"{momentum_translational_lift(params):.2g} kg/m")}[kind]
    text = f"plausible {lower * scale:g} .. {upper * scale:g}{unit} ({source})"
    return float(score), bool(score <= 1.0), text


#: a parameter is determined when its posterior spread is below this fraction of its prior's
#: (the rule a value is printed by, and a shared thrust-curve slope kept by)
DETERMINED = 0.5


def hover_thrust_per_speed(params: VehicleParams) -> float:
    """The hover thrust per rad/s of hover speed, ``b Omega_h`` (N s/rad): the unit of a
    thrust curve's linear term (:data:`PRIORS` kind ``hover``)."""
    from ..vehicle.params import hover_speed

    return params.thrust_factor * hover_speed(params)


def curve_slope_sd(params: VehicleParams) -> float:
    """Prior spread (N s/rad) of a thrust curve's linear term: half the plausible range of
    :data:`PRIORS` ``thrust_curve.linear`` (a fraction of the hover thrust per rad/s), in
    SI for ``params``."""
    lower, upper = PRIORS["thrust_curve.linear"][:2]
    return 0.5 * max(abs(lower), abs(upper)) * hover_thrust_per_speed(params)


#: prior spread of a thrust curve's curvature about the hover, as a fraction of b (the
#: b Omega^2 that gives the hover thrust there): stand fits T = k2 W^2 + k1 W + k0 read
#: k2 = 1.10-1.26 b at 40-60 % of the top speed (KDE2814 motor, 10 and 14 inch propellers:
#: Du et al., "Computational Multicopter Design", 2016, measured sweeps), and the published
#: curves of l2f's vehicle files with a large linear term (fs.h, flightmare.h, mrs.h) read
#: k2 = 0.40-0.42 b at their vehicles' hover. Half of b covers both.
CURVE_QUADRATIC_SD = 0.5


def curve_quadratic_bounds(params: VehicleParams) -> tuple[float, float]:
    """Bounds (N s^2/rad^2) of a thrust curve's curvature about the hover: the whole
    curvature ``b + quadratic`` from -b to 2 b. Below zero: a curve that flattens towards
    full throttle (l2f's arpl.h: k2 = -0.04 of the b at its hover, a motor that saturates)."""
    return -2.0 * params.thrust_factor, params.thrust_factor


def curve_quadratic_sd(params: VehicleParams) -> float:
    """Prior spread (N s^2/rad^2) of the curvature a thrust curve adds about the hover
    (``thrust_curve.quadratic``): :data:`CURVE_QUADRATIC_SD` times b."""
    return CURVE_QUADRATIC_SD * params.thrust_factor


def momentum_rate_damping(params: VehicleParams) -> float:
    """k_mt = r^2 T_h / v_i (N m s/rad): roll/pitch damping of the rotor discs' inflow change
    by momentum theory (r the largest hub distance from the centre, m; T_h = m g / R the hover
    thrust per rotor, N; v_i = sqrt(T_h / (2 rho pi R_p^2)) the hover induced velocity, m/s)."""
    import numpy as np

    arm = float(np.max(np.linalg.norm(params.rotor_positions[:, :2], axis=1)))
    thrust = params.mass * params.gravity / params.rotor_count
    induced = np.sqrt(thrust / (2 * params.air_density * np.pi * params.rotor_radius ** 2))
    return arm ** 2 * thrust / float(induced)


def momentum_translational_lift(params: VehicleParams) -> float:
    """k_tl = T_h / (4 v_i^2) (kg/m): the translational-lift coefficient of momentum theory
    (table above; T_h the hover thrust per rotor, N; v_i^2 = T_h / (2 rho pi R_p^2) the
    hover induced velocity squared, as in :func:`momentum_rate_damping`), which is
    k_tl = rho pi R_p^2 / 2 (rho the air density, kg/m^3; R_p the rotor radius, m)."""
    return 0.5 * params.air_density * math.pi * params.rotor_radius ** 2


def candidate_plausibility(values: dict, params: VehicleParams):
    """(score, plausible, text) of a whole fitted candidate: its least plausible parameter.

    A per-rotor mismatch is split into its mean (judged as a uniform thrust-per-Omega^2
    change, ``thrust_factor.change``) and each rotor's deviation from that mean (judged as a
    mismatch): four rotors all 16 % weak are a uniform loss, not four damaged props."""
    values = dict(values)
    rotors = {k: v for k, v in values.items() if k.startswith("thrust_mismatch.rotor_")}
    if len(rotors) > 1:
        mean = sum(rotors.values()) / len(rotors)
        for k in rotors:
            values[k] = rotors[k] - mean
        values["thrust_factor.change"] = mean
    scores = [plausibility(k, v, params) for k, v in values.items()]
    return max(scores, key=lambda s: s[0]) if scores else (NO_PRIOR_SCORE, True, "")
