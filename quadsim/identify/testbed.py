"""Identification of the report's testbed from its bench tables (everything in one result).

:func:`identify_testbed` reads the packaged tables (or the paths given) and returns a
:class:`TestbedIdentification`: thrust factor b per motor and pooled with 95 % intervals,
alternative thrust curves scored on held-out data, the PWM -> speed map with its saturation,
d from the stored torque/thrust ratio, the implied figure of merit, the bifilar inertia
(corrected) with its physical checks, the lumped-model inertia, and the CFD-table b for the
computational model. :mod:`quadsim.identify.audit` compares it with the published numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .benchdata import (
    ForceLift,
    SpeedSweep,
    load_cfd_table,
    load_force_lift,
    load_physical_measurements,
    load_testbed_constants,
    load_torque_thrust_ratio,
)
from .bifilar import load_bifilar_table
from .fits import MODELS, Fit, HeldOutScore, figure_of_merit, fit_curve, held_out_scores
from .inertia import BifilarResult, analyse_bifilar, lumped_inertia

__all__ = [
    "FM_PLAUSIBLE",
    "CurveEffect",
    "MotorMapFit",
    "TestbedIdentification",
    "curve_effect",
    "identification_to_json",
    "identify_testbed",
    "motor_map_fit",
]

#: Hover figure of merit of real propellers; outside this range b and d do not fit together.
FM_PLAUSIBLE = (0.3, 0.7)


@dataclass(frozen=True)
class MotorMapFit:
    """PWM -> steady speed: ``command`` (K,), ``speed`` (M, K) trial means (rad/s),
    ``spread`` (M, K) trial standard deviations, ``gain`` (K-1,) mean rad/s per PWM unit
    between steps, ``saturation_command`` the first command after which the gain falls
    below a quarter of its largest (low-speed) value (None if it never does)."""

    command: np.ndarray
    speed: np.ndarray
    spread: np.ndarray
    gain: np.ndarray
    saturation_command: float | None
    max_speed: float


def motor_map_fit(lift: ForceLift) -> MotorMapFit:
    """Mean speed per motor and command; where the speed gain per command step collapses."""
    speed = lift.speed.mean(axis=1)
    spread = lift.speed.std(axis=1, ddof=1)
    gain = np.diff(speed.mean(axis=0)) / np.diff(lift.command)
    running = speed.mean(axis=0)[:-1] > 0
    low = np.flatnonzero(running & (gain < 0.25 * float(gain[running].max())))
    saturation = float(lift.command[low[0]]) if low.size else None
    return MotorMapFit(lift.command, speed, spread, gain, saturation,
                       float(speed[:, -1].max()))


@dataclass(frozen=True)
class CurveEffect:
    """How much of the quadratic model's held-out error a better thrust curve removes.

    ``share`` = 1 - MSE(best alternative) / MSE(quadratic); ``biased_commands``: the
    commands where the quadratic's mean held-out residual is more than 2 standard errors
    from zero, with that residual (N, measured - predicted)."""

    scheme: str
    best_model: str
    quadratic_rms: float
    best_rms: float
    share: float
    biased_commands: list[tuple[float, float]]

    def to_json(self) -> dict:
        return {"scheme": self.scheme, "best_model": self.best_model,
                "quadratic_rms_N": self.quadratic_rms, "best_rms_N": self.best_rms,
                "share_of_quadratic_mse": self.share,
                "biased_commands": [{"command": c, "mean_residual_N": r}
                                    for c, r in self.biased_commands]}


def curve_effect(scores: list[HeldOutScore], command: np.ndarray) -> CurveEffect:
    """Summarise one scheme's scores (see :class:`CurveEffect`)."""
    by_model = {s.model: s for s in scores}
    quad = by_model["quadratic"]
    best = min((s for s in scores if s.model != "quadratic"), key=lambda s: s.rms)
    biased = [(float(c), float(b)) for c, b, e in
              zip(command, quad.bias_by_step, quad.stderr_by_step) if abs(b) > 2.0 * e]
    return CurveEffect(quad.scheme, best.model, quad.rms, best.rms,
                       1.0 - best.rms**2 / quad.rms**2, biased)


@dataclass(frozen=True)
class TestbedIdentification:
    """Everything identified about the testbed (SI units; see the module docstring)."""

    lift: ForceLift
    thrust_fits: dict[str, Fit]              # pooled, every model
    motor_fits: list[Fit]                    # quadratic, per motor
    top_point_b: np.ndarray                  # (M,) the report's method: F/Omega^2 at PWM 140
    held_out: dict[str, list[HeldOutScore]]  # scheme -> scores
    curve_effects: dict[str, CurveEffect]
    motor_map: MotorMapFit
    torque_thrust_ratio: float               # d/b (m)
    torque_thrust_ratio_ci95: tuple[float, float]
    torque_thrust_source: str
    drag_factor: float                       # d = ratio * b (N m s^2/rad^2)
    drag_factor_ci95: tuple[float, float]
    figure_of_merit: float
    cfd: SpeedSweep
    cfd_fit: Fit
    mass: float                              # kg, Table 4.4 mean
    arm_length: float                        # m, Table 4.4 motor-to-centre mean
    rotor_radius: float                      # m
    air_density: float                       # kg/m^3
    bifilar: BifilarResult
    lumped: np.ndarray                       # (3,) measured-mass lumped model, kg m^2
    lumped_report_inputs: np.ndarray         # (3,) eq. 3.18/3.19 with the report's inputs
    lumped_inputs: dict[str, float] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def thrust_factor(self) -> float:
        """Pooled least-squares b (N s^2/rad^2), quadratic through the origin."""
        return self.thrust_fits["quadratic"]["b"]

    @property
    def inertia_warning(self) -> str | None:
        """Why ``physical`` uses the lumped model instead of the bifilar test (None if not)."""
        if self.bifilar.physical:
            return None
        ixx, iyy, izz = self.bifilar.moments
        return ("inertia from the lumped model (eq. 3.18/3.19, Table 4.4 masses), NOT the "
                f"bifilar test: the corrected bifilar moments Ixx={ixx:.4g}, Iyy={iyy:.4g}, "
                f"Izz={izz:.4g} kg m^2 have Izz {izz / (ixx + iyy):.0f}x Ixx+Iyy, which no "
                "rigid body has, so the Table 4.14 periods cannot come from this vehicle; "
                + "; ".join(self.bifilar.problems))

    @property
    def inertia(self) -> np.ndarray:
        """(3,) principal moments for the physical set (bifilar if physical, else lumped)."""
        return self.bifilar.moments if self.bifilar.physical else self.lumped


def _lumped(physical) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    mean = {k: float(np.mean(physical[k])) for k in physical.columns if k != "trial"}
    # eq. 3.18/3.19 with the report's own inputs (M = base, l = frame length, m = motor)
    as_report = lumped_inertia(sphere_mass=mean["base_mass"], sphere_radius=mean["base_radius"],
                               arm_length=mean["frame_length"], point_mass=mean["motor_mass"])
    # the same model holding every measured gram: motor + propeller at the rotor hub, the
    # rest of the measured total (base, frames, battery, electronics) in the central sphere
    point = mean["motor_mass"] + mean["propeller_mass"]
    inputs = {"sphere_mass": mean["total_mass"] - 4.0 * point, "sphere_radius": mean["base_radius"],
              "arm_length": mean["motor_to_centre"], "point_mass": point}
    return lumped_inertia(**inputs), as_report, inputs


def identify_testbed(*, force_lift_paths=None, cfd_path=None, physical_path=None,
                     bifilar_path=None, bifilar_rig_path=None, ratio_path=None,
                     constants_path=None) -> TestbedIdentification:
    """Identify the testbed from the packaged report tables (or the paths given)."""
    lift = load_force_lift(force_lift_paths)
    where = ", ".join(p.name for p in lift.paths)
    fits = {m: fit_curve(lift.speed, lift.thrust, m, where=where) for m in MODELS}
    motor_fits = [fit_curve(lift.speed[i], lift.thrust[i], where=str(lift.paths[i]))
                  for i in range(lift.speed.shape[0])]
    top = lift.thrust[:, :, -1].mean(axis=1) / lift.speed[:, :, -1].mean(axis=1) ** 2
    held = {"leave one motor out": held_out_scores(lift.speed, lift.thrust, axis=0,
                                                   scheme="leave one motor out"),
            "leave one trial out": held_out_scores(lift.speed, lift.thrust, axis=1,
                                                   scheme="leave one trial out")}
    effects = {k: curve_effect(v, lift.command) for k, v in held.items()}

    ratio_table = load_torque_thrust_ratio(ratio_path)
    ratio = float(ratio_table["ratio"][0])
    ratio_ci = (float(ratio_table["ci95_low"][0]), float(ratio_table["ci95_high"][0]))
    b = fits["quadratic"]["b"]
    b_low, b_high = fits["quadratic"].interval("b")
    # independent experiments: relative half-widths add in quadrature
    rel = math.hypot((b_high - b_low) / (2 * b), (ratio_ci[1] - ratio_ci[0]) / (2 * ratio))
    d = ratio * b
    constants = load_testbed_constants(constants_path)
    radius = float(constants["propeller_diameter"][0]) / 2.0
    rho = float(constants["air_density"][0])

    physical = load_physical_measurements(physical_path)
    mass = float(np.mean(physical["total_mass"]))
    arm = float(np.mean(physical["motor_to_centre"]))
    lumped, lumped_report, lumped_in = _lumped(physical)
    bifilar = analyse_bifilar(load_bifilar_table(bifilar_path, bifilar_rig_path),
                              vehicle_mass=mass, max_radius=arm + radius)
    cfd = load_cfd_table(cfd_path)
    return TestbedIdentification(
        lift=lift, thrust_fits=fits, motor_fits=motor_fits, top_point_b=top, held_out=held,
        curve_effects=effects, motor_map=motor_map_fit(lift), torque_thrust_ratio=ratio,
        torque_thrust_ratio_ci95=ratio_ci, torque_thrust_source=ratio_table.source,
        drag_factor=d, drag_factor_ci95=(d * (1 - rel), d * (1 + rel)),
        figure_of_merit=figure_of_merit(b, d, rho, radius), cfd=cfd,
        cfd_fit=fit_curve(cfd.speed, cfd.thrust, where=str(cfd.path)), mass=mass,
        arm_length=arm, rotor_radius=radius, air_density=rho, bifilar=bifilar, lumped=lumped,
        lumped_report_inputs=lumped_report, lumped_inputs=lumped_in,
        sources={"force_lift": "; ".join(lift.sources), "cfd": cfd.source,
                 "physical": physical.source, "constants": constants.source},
    )


def identification_to_json(ident: TestbedIdentification) -> dict:
    """Stable-keyed JSON-ready summary of :class:`TestbedIdentification` (SI units)."""
    mm = ident.motor_map
    return {
        "thrust_factor": {
            "pooled": {m: f.to_json() for m, f in ident.thrust_fits.items()},
            "per_motor": [f.to_json() for f in ident.motor_fits],
            "top_point_per_motor": ident.top_point_b.tolist(),
            "held_out": {k: [s.to_json() for s in v] for k, v in ident.held_out.items()},
            "curve_effect": {k: v.to_json() for k, v in ident.curve_effects.items()},
            "command": ident.lift.command.tolist(),
        },
        "motor_map": {"command_pwm": mm.command.tolist(), "speed_rad_s": mm.speed.tolist(),
                      "spread_rad_s": mm.spread.tolist(), "gain_rad_s_per_pwm": mm.gain.tolist(),
                      "saturation_command": mm.saturation_command, "max_speed": mm.max_speed},
        "drag_factor": {"value": ident.drag_factor, "ci95": list(ident.drag_factor_ci95),
                        "torque_thrust_ratio_m": ident.torque_thrust_ratio,
                        "torque_thrust_ratio_ci95": list(ident.torque_thrust_ratio_ci95),
                        "source": ident.torque_thrust_source},
        "figure_of_merit": {"value": ident.figure_of_merit, "plausible_range": list(FM_PLAUSIBLE),
                            "plausible": FM_PLAUSIBLE[0] <= ident.figure_of_merit
                            <= FM_PLAUSIBLE[1]},
        "computational_thrust_factor": ident.cfd_fit.to_json(),
        "inertia": {"bifilar": ident.bifilar.to_json(),
                    "lumped_measured_masses_kg_m2": ident.lumped.tolist(),
                    "lumped_inputs": ident.lumped_inputs,
                    "lumped_report_inputs_kg_m2": ident.lumped_report_inputs.tolist(),
                    "physical_set_uses": "bifilar" if ident.bifilar.physical else "lumped",
                    "physical_set_kg_m2": ident.inertia.tolist()},
        "mass_kg": ident.mass, "arm_length_m": ident.arm_length,
        "rotor_radius_m": ident.rotor_radius, "air_density_kg_m3": ident.air_density,
        "warnings": [ident.inertia_warning] if ident.inertia_warning else [],
    }
