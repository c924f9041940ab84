"""The complete parameter set written by ``identify --logs``: the skeleton plus what the logs
identified, each ``source`` naming the fit, the logs and the fit quality; values the data
could not determine keep the user's value (or the documented default of
:mod:`.from_logs`) and are listed under ``warnings`` in the file and on stderr. The set is
loaded back with every check of :func:`quadsim.vehicle.params.load_params` (units, physical
inertia, the feasibility guards) before it is written; a set that fails is not written.

Defaults for what neither the skeleton nor the logs give: inertia
:data:`~quadsim.identify.from_logs.DEFAULT_INERTIA` x m r^2; d = :data:`DEFAULT_D_OVER_BR`
x b x rotor radius (the testbed's 10-inch propeller 0.116, the Crazyflie's 0.22), or
b x :data:`DEFAULT_D_OVER_B` m without a radius; max_speed the highest speed of the
motor map (cmd 1 at the reference voltage) or the highest logged.
"""

from __future__ import annotations

import copy
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import InputError, ModelError
from ..core.files import render_toml
from ..vehicle.params import VehicleParams, load_params
from .logseries import LogIdentification, Skeleton
from .skeleton import quantity

DEFAULT_D_OVER_BR = 0.15
DEFAULT_D_OVER_B = 0.01   # m
#: d is identified when its 95 % half-width is below this fraction of the value.
DRAG_CI = 0.3


@dataclass
class SetReport:
    """What to print: one line per identified or kept value; warnings for stderr."""

    lines: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def __iter__(self):
        return iter(self.lines)


def _relocate_cad(data: dict, skeleton_path: Path, output: Path) -> None:
    """Rewrite ``from_cad`` paths (relative to the skeleton) relative to the output."""
    for section in ("body", "rotor_layout"):
        spec = data.get(section, {}).get("from_cad") if isinstance(data.get(section), dict) \
            else None
        if isinstance(spec, dict) and "path" in spec:
            target = (skeleton_path.parent / spec["path"]).resolve()
            spec["path"] = Path(os.path.relpath(target, output.resolve().parent)).as_posix()


def _load_text(text: str, output: Path, *, check: bool) -> VehicleParams:
    folder = output.resolve().parent
    fd, tmp = tempfile.mkstemp(prefix=f".{output.stem}.", suffix=".toml", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
        return load_params(tmp, check=check)
    except (InputError, ModelError) as exc:   # name the output, not the temporary file
        raise type(exc)(str(exc).replace(tmp, f"{output} (as identified, not written)")) \
            from None
    finally:
        os.unlink(tmp)


def _fmt_ci(ci) -> str:
    return f"[{ci[0]:.4g}, {ci[1]:.4g}]"


def flapping_lines(ident: LogIdentification, logs: str = "") -> list[str]:
    """One line per blade-flapping axis (value, 95 % interval, how, and ``logs`` when
    given); those not identified say why."""
    out = []
    tail = f"; {logs}" if logs else ""
    for axis, e in zip(("roll", "pitch"), ident.flapping):
        if e.identified:
            out.append(f"blade_flapping {axis} = {e.value:.4g} kg m/rad, 95 % {_fmt_ci(e.ci95)}"
                       f" (identify --logs: {e.quality}{tail})")
        else:
            out.append(f"blade_flapping {axis}: {e.why} ({e.quality}{tail})")
    return out


def flapping_effects(ident: LogIdentification, params_name: str, log_names: str) -> str | None:
    """The text of an effect file (:mod:`quadsim.effects.effectfile`) for the set
    ``params_name``: ``blade_flapping`` with each identified axis, its value and source
    (the fit, its 95 % interval, the logs); None when no axis is identified."""
    from ..effects.effectfile import render_effect_file

    values = {axis: (float(f"{e.value:.6g}"),
                     f"python -m quadsim.identify --logs on {log_names}: {e.quality}; 95 % "
                     f"{_fmt_ci(e.ci95)}")
              for axis, e in zip(("roll", "pitch"), ident.flapping) if e.identified}
    if not values:
        return None
    header = ("Written by python -m quadsim.identify --logs --write-effects (rerun it instead "
              f"of editing by hand): blade_flapping on {params_name}.")
    return render_effect_file(params_name, f"{params_name} plus the blade flapping its logs "
                              "determine", [("blade_flapping", values)], header)


def build_set(data: dict, skeleton: Skeleton, ident: LogIdentification, log_names: str,
              drag_fit, output: Path) -> tuple[str, VehicleParams, SetReport]:
    """(TOML text, loaded params, report) of the complete set. ``drag_fit(provisional)``
    returns (d, se) from the logs (nan when it cannot)."""
    data = copy.deepcopy(data)
    _relocate_cad(data, Path(skeleton.path), Path(output))
    report = SetReport()
    logs = f"logs {log_names}"
    rotors = data.setdefault("rotors", {})
    body = data.setdefault("body", {})
    b = ident.thrust
    rotors["thrust_factor"] = quantity(
        float(f"{b.value:.6g}"), "N s^2/rad^2",
        f"identify --logs: {b.quality}; 95 % {_fmt_ci(b.ci95)}; {logs}")
    report.lines.append(f"b = {b.value:.5g} N s^2/rad^2, 95 % {_fmt_ci(b.ci95)} ({b.quality})")
    for name, value, se in ident.per_log_thrust:
        report.lines.append(f"  {name}: b = {value:.5g} +- {1.96 * se:.2g}")
    report.lines.append(ident.curve)
    report.lines += ident.notes

    motor = ident.motor_map
    if motor is not None:
        if ident.command_only:
            command, speed = motor["command"], motor["speed"]
            src = f"identify --logs, commands only: Omega(u) = sqrt(T(u) / b); {logs}"
        else:
            command = [0.0, 1.0]
            speed = [[round(a, 2), round(e, 2)] for a, e in motor["speed"]]
            lo, hi = motor["command_range"]
            src = (f"identify --logs: per-rotor Omega = a + k cmd, R^2 "
                   f"{min(motor['r2']):.3f}-{max(motor['r2']):.3f} over {motor['samples']} "
                   f"samples (flown cmd {lo:.2f}-{hi:.2f}, saturated commands left out); {logs}")
            report.lines.append(f"motor map: {src.split(';')[0]}; lag "
                                f"{1000 * motor['time_constant']:.1f} ms "
                                f"(95 % {1000 * motor['time_constant_ci'][0]:.1f}-"
                                f"{1000 * motor['time_constant_ci'][1]:.1f} ms)")
        mm = {"command_unit": "1", "command": quantity(command, "1", src),
              "speed": quantity(speed, "rad/s", src)}
        if motor["reference_voltage"] is not None:
            mm["reference_voltage"] = quantity(round(motor["reference_voltage"], 4), "V",
                                               f"median battery voltage of the {logs}")
            how = ("v / v_ref scaling of the command (commands only)" if ident.command_only
                   else f"fitted with the map (per-rotor spread "
                        f"{motor.get('voltage_gain_spread', 0.0):.2g} 1/V)")
            mm["voltage_gain"] = quantity(float(f"{motor['voltage_gain']:.5g}"), "1/V",
                                          f"identify --logs: {how}; {logs}")
            report.lines.append(f"voltage gain {motor['voltage_gain']:.4g} 1/V at "
                                f"{motor['reference_voltage']:.3f} V")
        if motor.get("time_constant") is not None:
            how = ("the lagged commands' thrust and roll/pitch balances (IMU + commands)"
                   if ident.command_only else "first-order lag")
            mm["time_constant"] = quantity(
                motor["time_constant"], "s",
                f"identify --logs: {how}, grid 0-200 ms, 95 % "
                f"{motor['time_constant_ci'][0]:.4f}-{motor['time_constant_ci'][1]:.4f} s; {logs}")
        data["motor_map"] = mm
    if "max_speed" not in rotors:
        top = float(np.max(np.asarray(data["motor_map"]["speed"]["value"]))) \
            if "motor_map" in data else None
        if top is None:
            raise InputError(f"{skeleton.path}: rotors.max_speed: missing and the logs have "
                             "no commands to map")
        rotors["max_speed"] = quantity(round(top, 1), "rad/s",
                                       "identify --logs: motor map at full command")
    inertia = np.diag(np.asarray(body["inertia"]["value"], float)) if "inertia" in body \
        else None
    values = [e.value for e in ident.inertia]
    izz = float(inertia[2]) if inertia is not None else float(
        skeleton.mass * np.mean(np.sum((skeleton.positions - skeleton.com)[:, :2] ** 2, 1))
        * 0.35)
    diag = [values[0], values[1], izz]
    sources = []
    for name, e in zip(("Ixx", "Iyy"), ident.inertia):
        if e.identified:
            sources.append(f"{name} identified ({e.quality}, 95 % {_fmt_ci(e.ci95)})")
            report.lines.append(f"{name} = {e.value:.4g} kg m^2, 95 % {_fmt_ci(e.ci95)}")
        else:
            sources.append(f"{name} kept ({e.why})")
            report.lines.append(f"{name} = {e.value:.4g} kg m^2 kept: {e.why}")
    izz_why = ("Izz kept from the skeleton" if inertia is not None else
               "Izz default 0.35 m r^2") + (" (not identified without rotor speeds)"
                                            if ident.command_only else
                                            " (only d/Izz shows in yaw; d is identified given it)")
    sources.append(izz_why)
    report.lines.append(izz_why)
    old_source = body["inertia"]["source"] if "inertia" in body else "none given"
    if "from_cad" not in body:
        matrix = [[diag[0], 0.0, 0.0], [0.0, diag[1], 0.0], [0.0, 0.0, diag[2]]]
        body["inertia"] = quantity(matrix, "kg m^2",
                                   "; ".join(sources) + f"; skeleton: {old_source}; {logs}")
        body.setdefault("com", quantity([0.0, 0.0, 0.0], "m", "default: symmetric frame"))

    radius = float(rotors["radius"]["value"]) if "radius" in rotors else None
    d_default = b.value * (DEFAULT_D_OVER_BR * radius if radius else DEFAULT_D_OVER_B)
    given_d = "drag_factor" in rotors
    rotors.setdefault("drag_factor", quantity(float(f"{d_default:.5g}"), "N m s^2/rad^2",
                                              "default (provisional)"))
    provisional = _load_text(render_toml(data, "provisional"), output, check=False)
    d, se = drag_fit(provisional) if not ident.command_only else (float("nan"),) * 2
    if np.isfinite(d) and d > 0 and 1.96 * se < DRAG_CI * d:
        rotors["drag_factor"] = quantity(
            float(f"{d:.5g}"), "N m s^2/rad^2",
            f"identify --logs: yaw torque, instrumental variables (commanded speeds; "
            f"quadsim.gap.fitting.drag_refit_iv) given Izz {izz:.4g}; 95 % "
            f"[{d - 1.96 * se:.4g}, {d + 1.96 * se:.4g}]; {logs}")
        report.lines.append(f"d = {d:.4g} N m s^2/rad^2, 95 % [{d - 1.96 * se:.4g}, "
                            f"{d + 1.96 * se:.4g}] (d/b = {d / b.value:.3g} m)")
    else:
        why = ("no commands and rotor speeds together" if not np.isfinite(d) else
               f"IV estimate {d:.3g} +- {1.96 * se:.2g} too uncertain (weak yaw excitation)")
        kept = "the skeleton's value" if given_d else (
            f"the default {DEFAULT_D_OVER_BR} x b x radius" if radius
            else f"the default b x {DEFAULT_D_OVER_B} m")
        if not given_d:
            rotors["drag_factor"]["source"] = f"default: {kept} (not identified: {why})"
        report.warnings.append(f"d not identified ({why}): {kept} kept")
        report.lines.append(f"d = {float(rotors['drag_factor']['value']):.4g} N m s^2/rad^2 "
                            f"kept: {why}")
    report.lines += flapping_lines(ident)
    report.warnings += [e.why for e in ident.flapping if not e.identified]
    data["notes"] = list(data.get("notes", [])) + [ident.curve, *ident.notes,
                                                   *flapping_lines(ident, logs)]
    warnings = list(ident.warnings) + report.warnings
    if warnings:
        data["warnings"] = list(data.get("warnings", [])) + warnings
    header = (f"Parameter set {data.get('name', Path(output).stem)!r}: the skeleton "
              f"{Path(skeleton.path).name} plus what `python -m quadsim.identify --logs` "
              f"identified\nfrom {log_names} (rerun the command instead of editing by hand).")
    text = render_toml(data, header)
    params = _load_text(text, output, check=True)
    return text, params, report
