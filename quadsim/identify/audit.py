"""Report audit: what the 2015 report got wrong, each with the numbers that show it.

:func:`audit_report` compares the published parameter set (``models/report.toml``, loaded
with ``check=False``) with the identification from the report's own tables and returns one
:class:`Finding` per check, ``found`` True when the error is present:

* ``two_pi_thrust_factor``: the model's b is the per-motor b times 2 pi;
* ``drag_unmeasured``: d = b/4 exactly although no torque was measured, and the pair implies
  an impossible figure of merit;
* ``bifilar_missing_square``: the published inertias follow I = [T/(2 pi)] m g R^2/L, not
  I = m g R^2 T^2/(4 pi^2 L);
* ``published_inertia_unphysical``: the published tensor breaks the triangle inequality;
* ``bifilar_periods_not_this_vehicle``: even corrected, the periods give a tensor no rigid
  body of this size has;
* ``top_point_thrust_factor``: b from the top point only is outside the 95 % interval of
  the least-squares b over all points;
* ``saturation_claim``: the report says speed stops rising above PWM 130; the tables say
  how much it still rises.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..vehicle.params import VehicleParams, inertia_problems
from .fits import figure_of_merit
from .testbed import FM_PLAUSIBLE, TestbedIdentification

__all__ = ["Finding", "audit_report"]


@dataclass(frozen=True)
class Finding:
    """One audit check: ``found`` True when the report has the error."""

    key: str
    title: str
    found: bool
    detail: str
    numbers: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"key": self.key, "title": self.title, "found": self.found,
                "detail": self.detail, "numbers": self.numbers}


def _two_pi(ident: TestbedIdentification, report: VehicleParams) -> Finding:
    per_motor = float(np.mean(ident.top_point_b))
    ratio = report.thrust_factor / per_motor
    return Finding(
        "two_pi_thrust_factor", "model b is the per-motor b times 2 pi",
        abs(ratio / (2 * math.pi) - 1) < 0.01,
        f"published b = {report.thrust_factor:.5g} N s^2/rad^2 is {ratio:.4f} x the mean "
        f"per-motor b = {per_motor:.4g} (the report's own top-point method; 2 pi = "
        f"{2 * math.pi:.4f}) and {report.thrust_factor / ident.thrust_factor:.3f} x the pooled "
        f"least-squares b = {ident.thrust_factor:.4g}: all four rotors would lift "
        f"{4 * report.thrust_factor * report.max_speed**2 / 9.81:.1f} kg at full speed, "
        f"the bench measured {4 * ident.lift.thrust[:, :, -1].mean() / 9.81:.2f} kg",
        {"published_b": report.thrust_factor, "per_motor_b": per_motor, "ratio": ratio,
         "pooled_b": ident.thrust_factor})


def _drag(ident: TestbedIdentification, report: VehicleParams) -> Finding:
    ratio = report.drag_factor / report.thrust_factor
    fm = figure_of_merit(report.thrust_factor, report.drag_factor, ident.air_density,
                         ident.rotor_radius)
    return Finding(
        "drag_unmeasured", "d = b/4, never measured, implies an impossible figure of merit",
        abs(ratio - 0.25) < 1e-3 or not FM_PLAUSIBLE[0] <= fm <= FM_PLAUSIBLE[1],
        f"published d/b = {ratio:.4f} m (exactly b/4; the report has no torque measurement); "
        f"a measured 10-inch propeller gives d/b = {ident.torque_thrust_ratio:.4g} m "
        f"({ratio / ident.torque_thrust_ratio:.0f}x smaller); the published b, d imply "
        f"FM = {fm:.3f} (real propellers {FM_PLAUSIBLE[0]}-{FM_PLAUSIBLE[1]}), ours "
        f"{ident.figure_of_merit:.3f}",
        {"published_d_over_b_m": ratio, "measured_d_over_b_m": ident.torque_thrust_ratio,
         "published_fm": fm, "identified_fm": ident.figure_of_merit})


def _bifilar_square(ident: TestbedIdentification, report: VehicleParams) -> Finding:
    published = np.diag(report.inertia)
    unsquared = ident.bifilar.published
    mismatch = float(np.max(np.abs(unsquared / published - 1)))
    corrected = ident.bifilar.moments
    return Finding(
        "bifilar_missing_square", "bifilar formula lacks T^2",
        mismatch < 0.01 and float(np.max(np.abs(corrected / published - 1))) > 0.05,
        f"I = [T/(2 pi)] m g R^2/L on the Table 4.14 periods reproduces the published "
        f"{published.tolist()} within {100 * mismatch:.2f} %; the correct m g R^2 T^2/(4 pi^2 L) "
        f"gives Ixx, Iyy, Izz = {corrected[0]:.4g}, {corrected[1]:.4g}, {corrected[2]:.4g} kg m^2 "
        "(a factor T/(2 pi) apart; the report's unit kg m^2/s gives it away)",
        {"max_relative_mismatch_unsquared": mismatch, "corrected_ixx": float(corrected[0]),
         "corrected_izz": float(corrected[2])})


def _published_unphysical(report: VehicleParams) -> Finding:
    problems = inertia_problems(report.inertia)
    moments = np.diag(report.inertia)
    return Finding(
        "published_inertia_unphysical", "published inertia breaks the triangle inequality",
        bool(problems),
        "; ".join(problems) if problems else "published inertia is physical",
        {"ixx_plus_iyy": float(moments[0] + moments[1]), "izz": float(moments[2])})


def _bifilar_vehicle(ident: TestbedIdentification) -> Finding:
    ixx, iyy, izz = ident.bifilar.moments
    return Finding(
        "bifilar_periods_not_this_vehicle", "corrected bifilar inertia is not this vehicle's",
        not ident.bifilar.physical,
        ("; ".join(ident.bifilar.problems) + f". The lumped model of the measured masses gives "
         f"{ident.lumped[0]:.4g}, {ident.lumped[1]:.4g}, {ident.lumped[2]:.4g} kg m^2: the "
         "roll/pitch periods are ~2x too short for it, the yaw period ~3x too long")
        if ident.bifilar.problems else "corrected bifilar inertia passes every check",
        {"izz_over_ixx_plus_iyy": float(izz / (ixx + iyy)),
         "max_radius_m": ident.bifilar.max_radius})


def _top_point(ident: TestbedIdentification) -> Finding:
    low, high = ident.thrust_fits["quadratic"].interval("b")
    top = ident.top_point_b
    outside = (top < low) | (top > high)
    return Finding(
        "top_point_thrust_factor", "b from the top point only, not from all points",
        bool(np.any(outside)),
        f"top-point b per motor {np.array2string(top, precision=4)} vs pooled least squares "
        f"{ident.thrust_factor:.4g} (95 % [{low:.4g}, {high:.4g}]); "
        f"{int(outside.sum())} of {top.size} outside",
        {"top_point_b_mean": float(top.mean()), "pooled_b": ident.thrust_factor})


def _saturation(ident: TestbedIdentification) -> Finding:
    mm = ident.motor_map
    mean = mm.speed.mean(axis=0)
    at = int(np.argmin(np.abs(mm.command - 130.0)))
    rise = float(mean[-1] / mean[at] - 1) if at < mean.size - 1 else 0.0
    return Finding(
        "saturation_claim", "'no speed increase above PWM 130' is not what the tables show",
        rise > 0.02,
        f"mean speed {mean[at]:.1f} rad/s at PWM {mm.command[at]:g} and {mean[-1]:.1f} rad/s at "
        f"PWM {mm.command[-1]:g} (+{100 * rise:.1f} %); the gain per PWM step does fall: "
        f"{np.array2string(mm.gain, precision=2)} rad/s per PWM unit",
        {"speed_at_130": float(mean[at]), "speed_at_top": float(mean[-1]), "rise": rise})


def audit_report(ident: TestbedIdentification, report: VehicleParams) -> list[Finding]:
    """Every audit check (see the module docstring); ``report`` loaded with check=False."""
    return [_two_pi(ident, report), _drag(ident, report), _bifilar_square(ident, report),
            _published_unphysical(report), _bifilar_vehicle(ident), _top_point(ident),
            _saturation(ident)]
