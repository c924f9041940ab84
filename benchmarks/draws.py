"""Random realistic magnitudes of hidden effects, per vehicle (shared by every benchmark source).

:func:`draw` returns quadsim effects (library or :mod:`.outside`) for the self-generated and
pipeline sources; :func:`draw_rotorpy` returns the same physical changes as RotorPy
parameters (:data:`benchmarks.rotorpy_source.EFFECTS`) and :func:`library_equivalent`
maps those back to the library effect with the true values (used only to check that a case
is observable, never by the diagnosis). Magnitudes (SI): added mass 5-20 % of the vehicle;
CoM offset 3-10 % of the arm; inertia 15-40 % per axis; one rotor 5-15 % weaker/stronger; all
rotors' thrust per Omega^2 5-15 % lower or 2-5 % higher (``thrust_factor``: worn props, heat or
altitude lose up to 15 %; cold air or another prop batch gain a few %, the prior of
quadsim.gap.fitting); motor time constant 20-50 ms (x2 for the 0.84 kg vehicle); drag at 1.5 m/s 1-4
% of the weight; rotor drag 0.5-2 x 2.5 % of the weight per m/s at hover; wind 0-2 m/s.
"""

from __future__ import annotations

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.effects import make_effect
from quadsim.effects.battery_sag import nominal_voltage
from quadsim.vehicle.params import VehicleParams, hover_speed

from .outside import BladeFlapping

__all__ = ["draw", "draw_rotorpy", "library_equivalent"]


def _drag_k(params: VehicleParams, rng) -> float:
    per_rotor = params.rotor_count * hover_speed(params)
    return rng.uniform(0.5, 2.0) * 0.025 * params.weight / per_rotor


def _inertia(params: VehicleParams, rng) -> np.ndarray:
    while True:  # redraw until the changed vehicle is still a rigid body
        e = rng.uniform(0.15, 0.4, 3) * rng.choice([-1.0, 1.0], 3)
        try:
            make_effect("inertia_error", xx=e[0], yy=e[1], zz=e[2]).apply_to_params(params)
            return e
        except ModelError:
            continue


def draw(name: str, params: VehicleParams, rng: np.random.Generator) -> list:
    """Hidden quadsim effect(s) ``name`` at a random realistic magnitude for this vehicle."""
    m, w = params.mass, params.weight
    hover = hover_speed(params)
    arm = float(np.linalg.norm(params.rotor_positions[0]))
    sign = rng.choice([-1.0, 1.0])
    small = params.mass < 0.1
    drag_k = _drag_k(params, rng)
    if name == "mass_offset":
        return [make_effect(name, mass=rng.uniform(0.05, 0.2) * m)]
    if name == "com_offset":
        r = rng.uniform(0.03, 0.1) * arm
        a = rng.uniform(0, 2 * np.pi)
        return [make_effect(name, x=r * np.cos(a), y=r * np.sin(a))]
    if name == "inertia_error":
        e = _inertia(params, rng)
        return [make_effect(name, xx=e[0], yy=e[1], zz=e[2])]
    if name == "thrust_mismatch":
        rotor = int(rng.integers(1, params.rotor_count + 1))
        return [make_effect(name, **{f"rotor_{rotor}": sign * rng.uniform(0.05, 0.15)})]
    if name == "thrust_curve":
        linear = sign * rng.uniform(0.03, 0.1) * params.thrust_factor * hover
        return [make_effect(name, linear=linear)]
    if name == "thrust_factor":   # within the documented prior -15 % .. +5 % (gap.priors);
        # the motors are driven like a battery drives them (speed per command ~ voltage), so
        # the load change moves their speed per command too: DC motors at 60-90 % voltage
        # efficiency (quadsim.effects.thrust_factor)
        change = -rng.uniform(0.05, 0.15) if sign < 0 else rng.uniform(0.02, 0.05)
        return [make_effect(name, change=change, alpha=rng.uniform(0.1, 0.3))]
    if name == "battery_sag":
        return [make_effect(name, rate=rng.uniform(0.005, 0.02),
                            full_voltage=nominal_voltage(params))]
    if name == "ground_effect":
        return [make_effect(name, gain=rng.uniform(1.0, 2.0))]
    if name == "rotor_drag":
        return [make_effect(name, coefficient=drag_k)]
    if name == "body_drag":
        cd = rng.uniform(0.01, 0.04) * w / (0.5 * params.air_density * 1.5 ** 2)
        return [make_effect(name, cd_area=cd, cd_area_vertical=cd)]
    if name == "motor_lag":
        return [make_effect(name, time_constant=rng.uniform(0.02, 0.05) * (1 if small else 2))]
    if name == "gyroscopic":
        jr = rng.uniform(3e-8, 1e-7) if small else rng.uniform(3e-5, 8e-5)
        return [make_effect(name, rotor_inertia=jr)]
    if name == "wind":
        v = rng.uniform(-2, 2, 2)
        return [make_effect(name, vx=v[0], vy=v[1]), make_effect("rotor_drag", coefficient=drag_k)]
    if name == "rate_damping":   # library effect: damping time constant I/k of 1.3-4 s
        k = rng.uniform(0.25, 0.75) * np.diag(params.inertia)
        return [make_effect(name, x=k[0], y=k[1], z=k[2])]
    if name == "canted_rotor":   # library effect: a bent mount, 2-5 deg
        return [make_effect(name, rotor=float(rng.integers(1, params.rotor_count + 1)),
                            angle=sign * np.radians(rng.uniform(2.0, 5.0)),
                            azimuth=rng.uniform(-np.pi, np.pi))]
    if name == "translational_lift":   # +2-5 % of the hover thrust at 1.5 m/s
        return [make_effect(name, k_h=rng.uniform(0.02, 0.05) * w
                            / (params.rotor_count * 1.5 ** 2))]
    if name == "blade_flapping":   # outside: moment 2-4 % of weight x arm at 1 m/s
        return [BladeFlapping(k_flap=rng.uniform(0.02, 0.04) * w * arm
                              / (params.rotor_count * hover))]
    return []


#: quadsim library name of each RotorPy-injected effect (None: outside the library).
ROTORPY_TRUTH = {"mass_offset": "mass", "com_offset": "com", "inertia_error": "inertia",
                 "thrust_mismatch": "weak_rotor", "motor_lag": "tau_m", "body_drag": "c_d",
                 "rotor_drag": "k_d", "wind": "wind", "flapping": "k_flap",
                 "translational_lift": "k_h", "gust": "gust"}


def draw_rotorpy(name: str, params: VehicleParams, rng: np.random.Generator) -> dict:
    """The physical change ``name`` (a library name, or ``flapping``/``translational_lift``/
    ``gust`` outside it) as RotorPy effects (:mod:`.rotorpy_source`), SI units."""
    w, hover = params.weight, hover_speed(params)
    arm = float(np.linalg.norm(params.rotor_positions[0]))
    small = params.mass < 0.1
    drag_k = _drag_k(params, rng)
    if name == "mass_offset":
        return {"mass": rng.uniform(0.05, 0.2) * params.mass}
    if name == "com_offset":
        r, a = rng.uniform(0.03, 0.1) * arm, rng.uniform(0, 2 * np.pi)
        return {"com": (r * np.cos(a), r * np.sin(a))}
    if name == "inertia_error":
        return {"inertia": tuple(_inertia(params, rng))}
    if name == "thrust_mismatch":
        return {"weak_rotor": (int(rng.integers(1, params.rotor_count + 1)),
                               -rng.uniform(0.05, 0.15))}
    if name == "thrust_factor":
        return {"thrust_scale": -rng.uniform(0.05, 0.15)}
    if name == "motor_lag":
        return {"tau_m": rng.uniform(0.02, 0.05) * (1 if small else 2)}
    if name == "body_drag":
        return {"c_d": rng.uniform(0.01, 0.04) * w / 1.5 ** 2}
    if name == "rotor_drag":
        return {"k_d": drag_k}
    if name == "wind":
        v = rng.uniform(-2, 2, 2)
        return {"wind": (v[0], v[1]), "k_d": drag_k}
    if name == "flapping":   # moment ~2 % of weight x arm at 1 m/s, summed over rotors
        return {"k_flap": rng.uniform(1.0, 2.0) * 0.02 * w * arm / (params.rotor_count * hover)}
    if name == "translational_lift":   # +1.5-3 % thrust at 1.5 m/s
        return {"k_h": rng.uniform(0.015, 0.03) * w / (params.rotor_count * 1.5 ** 2)}
    if name == "gust":
        return {"gust": rng.uniform(1.0, 2.0), "k_d": drag_k}
    raise ValueError(f"no RotorPy form of {name!r}")


def library_equivalent(spec: dict, params: VehicleParams) -> list:
    """The library effects with the true values of a RotorPy ``spec`` ([] if none maps)."""
    out = []
    if "mass" in spec:
        out.append(make_effect("mass_offset", mass=spec["mass"]))
    if "com" in spec:
        out.append(make_effect("com_offset", x=spec["com"][0], y=spec["com"][1]))
    if "inertia" in spec:
        e = spec["inertia"]
        out.append(make_effect("inertia_error", xx=e[0], yy=e[1], zz=e[2]))
    if "weak_rotor" in spec:
        i, d = spec["weak_rotor"]
        out.append(make_effect("thrust_mismatch", **{f"rotor_{i}": d}))
    if "thrust_scale" in spec:
        out.append(make_effect("thrust_factor", change=spec["thrust_scale"]))
    if "tau_m" in spec:
        out.append(make_effect("motor_lag", time_constant=spec["tau_m"]))
    if "c_d" in spec:
        cd = 2.0 * spec["c_d"] / params.air_density
        out.append(make_effect("body_drag", cd_area=cd, cd_area_vertical=cd))
    if "wind" in spec:
        out.append(make_effect("wind", vx=spec["wind"][0], vy=spec["wind"][1]))
    if "k_h" in spec:           # RotorPy's lift: k_h (v_x^2 + v_y^2) per rotor, body axes
        out.append(make_effect("translational_lift", k_h=spec["k_h"]))
    if "k_d" in spec and "gust" not in spec:
        out.append(make_effect("rotor_drag", coefficient=spec["k_d"]))
    return out
