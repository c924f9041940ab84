"""python -m quadsim.identify: identify b, d, motor map and inertia; audit the report.

Reads the report's bench tables shipped in quadsim/identify/data (or the files given), fits the
rotor thrust factor b by least squares over every point and trial (95 % intervals),
scores alternative thrust curves on held-out motors and trials, maps PWM -> rotor speed
(with its saturation), derives d from a measured torque/thrust ratio, reports the implied
hover figure of merit, computes the bifilar inertia with the corrected T^2 formula and
checks that it is physical, and lists what the report got wrong, with numbers.

Output: human-readable tables (default) or one JSON object (--json, stable keys, SI units).
Exit status 2 with a one-line error on bad input (file and column named).

Your own vehicle (docs/own-vehicle.md)::

    python -m quadsim.identify --logs LOG... --vehicle SKELETON.toml -o VEHICLE.toml \
        [--write-effects EFFECTS.toml]

identifies b, d, the command -> speed map (with voltage and lag) and the inertia where the
manoeuvres excite it from flight logs (ground and idle spans cut, :mod:`quadsim.logs.spans`)
and writes a complete parameter set (:mod:`quadsim.identify.from_logs`); logs without rotor
speeds give the command (and voltage) -> thrust map from the accelerometer. The blade
flapping per axis (:mod:`quadsim.identify.flapping`) is printed with its interval and
written into the set's notes; ``--write-effects`` also writes it, where identified, as an
effect file for ``quadsim.gap --effects-file`` and the simulators (nothing is written when
neither axis is identified: a warning says why).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

from ..core.args import ArgumentParser
from ..core.errors import InputError, run_cli
from ..core.executor import limit_numeric_threads
from ..vehicle.params import load_params
from .audit import Finding, audit_report
from .benchdata import load_thrust_stand
from .fits import StandFit, figure_of_merit, fit_thrust_stand
from .testbed import FM_PLAUSIBLE, TestbedIdentification, identification_to_json, identify_testbed


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="python -m quadsim.identify", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON object (SI units)")
    parser.add_argument("--model", default="report", metavar="NAME|PATH",
                        help="parameter set whose published numbers the audit checks "
                             "(default: report)")
    parser.add_argument("--stand", type=Path, action="append", default=[], metavar="CSV",
                        help="also fit b and d on a thrust-stand sweep with columns esc_us, "
                             "torque_Nm, thrust_N, speed_rpm (repeatable)")
    parser.add_argument("--stand-radius", type=float, action="append", default=[],
                        metavar="M", help="propeller radius (m) of each --stand sweep, in order "
                        "(default: from a file name like 'kde2814_14inch_sweep.csv', else the "
                        "testbed's radius, said so)")
    parser.add_argument("--force-lift", type=Path, nargs="+", metavar="CSV",
                        help="force-lift tables, one per motor (default: report Tables 4.5, "
                             "4.7, 4.9, 4.11); header pwm[pwm], mass_1..3[kg], speed_1..3[rpm]")
    parser.add_argument("--cfd", type=Path, metavar="CSV", help="CFD thrust table (Table 4.2)")
    parser.add_argument("--physical", type=Path, metavar="CSV",
                        help="physical measurements (Table 4.4)")
    parser.add_argument("--bifilar", type=Path, metavar="CSV", help="bifilar periods (Table 4.14)")
    parser.add_argument("--bifilar-rig", type=Path, metavar="CSV",
                        help="bifilar rig constants (section 4.3.3)")
    own = parser.add_argument_group("your own vehicle from its flight logs")
    own.add_argument("--logs", type=Path, nargs="+", metavar="LOG",
                     help="flight logs (schema CSV/Parquet, PX4 ULog, Crazyflie uSD, ArduPilot "
                          "DataFlash) of one vehicle; needs --vehicle and -o")
    own.add_argument("--vehicle", type=Path, metavar="SKELETON.toml",
                     help="parameter set with mass and rotor geometry; thrust_factor, "
                          "drag_factor, max_speed, [motor_map] and inertia may be absent")
    own.add_argument("-o", "--output", type=Path, metavar="VEHICLE.toml",
                     help="complete parameter set to write (atomically; never the skeleton)")
    own.add_argument("--write-effects", type=Path, metavar="EFFECTS.toml",
                     help="also write an effect file with the blade flapping (roll, pitch) "
                          "the logs determine, for quadsim.gap --effects-file and the "
                          "simulators (quadsim.identify.flapping)")
    return parser


def _print_thrust(ident: TestbedIdentification) -> None:
    print("THRUST FACTOR b (F = b Omega^2, least squares over all points and trials)")
    print(f"  {'motor':<8}{'b [N s^2/rad^2]':>17}{'95 % interval':>26}{'rms [N]':>9}"
          f"{'top-point b':>13}")
    for i, fit in enumerate(ident.motor_fits):
        low, high = fit.interval("b")
        print(f"  {i + 1:<8}{fit['b']:>17.5g}   [{low:.5g}, {high:.5g}]{fit.rms:>9.3f}"
              f"{ident.top_point_b[i]:>13.5g}")
    pooled = ident.thrust_fits["quadratic"]
    low, high = pooled.interval("b")
    print(f"  {'pooled':<8}{pooled['b']:>17.5g}   [{low:.5g}, {high:.5g}]{pooled.rms:>9.3f}")
    print("\n  alternative thrust curves (rms in N; held out = predicted by a fit to the others)")
    print(f"  {'model':<18}{'parameters':<44}{'fit':>7}{'motor out':>11}{'trial out':>11}")
    held = {k: {s.model: s for s in v} for k, v in ident.held_out.items()}
    for model, fit in ident.thrust_fits.items():
        params = ", ".join(f"{n}={v:.4g}" for n, v in zip(fit.names, fit.params))
        print(f"  {model:<18}{params:<44}{fit.rms:>7.3f}"
              f"{held['leave one motor out'][model].rms:>11.3f}"
              f"{held['leave one trial out'][model].rms:>11.3f}")
    for effect in ident.curve_effects.values():
        where = ", ".join(f"PWM {c:g} ({r:+.2f} N)" for c, r in effect.biased_commands)
        print(f"  {effect.scheme}: the {effect.best_model} curve removes "
              f"{100 * effect.share:.0f} % of the quadratic's held-out squared error "
              f"(thrust-curve effect); quadratic biased at {where or 'no command'}")


def _print_motor_map(ident: TestbedIdentification) -> None:
    mm = ident.motor_map
    print("\nMOTOR MAP (PWM value -> steady speed, trial means, rad/s)")
    print("  " + f"{'PWM':>5}" + "".join(f"{'motor ' + str(i + 1):>10}"
                                       for i in range(mm.speed.shape[0])) + f"{'gain':>9}")
    for k, command in enumerate(mm.command):
        gain = f"{mm.gain[k - 1]:>9.2f}" if k else f"{'':>9}"
        print(f"  {command:>5g}" + "".join(f"{s:>10.1f}" for s in mm.speed[:, k]) + gain)
    sat = (f"gain falls below 1/4 of its low-speed value after PWM {mm.saturation_command:g}"
           if mm.saturation_command is not None else "no saturation found")
    print(f"  gain in rad/s per PWM unit; {sat}; max speed {mm.max_speed:.1f} rad/s "
          "(held above the last command)")


#: Above this hover figure of merit a small propeller is not physical (the best rotors
#: reach ~0.8; small propellers 0.3-0.7).
FM_MAX_PHYSICAL = 0.8
_INCH = re.compile(r"(\d+(?:\.\d+)?)[-_ ]?(?:inch|in)(?![a-z])", re.IGNORECASE)


def _fm_flag(fm: float) -> str:
    return (f"  [IMPLAUSIBLE: FM > {FM_MAX_PHYSICAL} is not physical for a small propeller; "
            "wrong radius?]" if fm > FM_MAX_PHYSICAL else "")


def stand_radii(paths, given, default: float) -> list[tuple[float, str]]:
    """Propeller radius (m) of each stand sweep and where it came from: ``--stand-radius``,
    else the diameter in inches in the file name (``14inch`` -> 0.1778 m), else ``default``."""
    out = []
    for i, path in enumerate(paths):
        if i < len(given):
            out.append((given[i], "--stand-radius"))
            continue
        match = _INCH.search(Path(path).name)
        if match:
            out.append((float(match.group(1)) * 0.0254 / 2,
                        f"{match.group(1)}-inch from the file name"))
        else:
            out.append((default, "testbed radius assumed"))
    return out


def _print_drag(ident: TestbedIdentification, stands: list[StandFit], radii=None) -> None:
    low, high = ident.torque_thrust_ratio_ci95
    fm = ident.figure_of_merit
    flag = "plausible" if FM_PLAUSIBLE[0] <= fm <= FM_PLAUSIBLE[1] else "IMPLAUSIBLE"
    print("\nDRAG FACTOR d (no torque measured on the testbed)")
    print(f"  d/b = {ident.torque_thrust_ratio:.5g} m  (95 % [{low:.5g}, {high:.5g}])")
    print(f"    source: {ident.torque_thrust_source}")
    print(f"  d = (d/b) b = {ident.drag_factor:.5g} N m s^2/rad^2  (95 % "
          f"[{ident.drag_factor_ci95[0]:.5g}, {ident.drag_factor_ci95[1]:.5g}])")
    print(f"  hover figure of merit FM = b^1.5/(d sqrt(2 rho pi R^2)) = {fm:.3f}  [{flag}; "
          f"R = {ident.rotor_radius:g} m, rho = {ident.air_density:g} kg/m^3]")
    cfd = ident.cfd_fit
    print(f"  computational (CFD Table 4.2) b = {cfd['b']:.5g} N s^2/rad^2 "
          f"(95 % [{cfd.interval('b')[0]:.5g}, {cfd.interval('b')[1]:.5g}])")
    for stand, (radius, how) in zip(stands, radii or [None] * len(stands)):
        b, d = stand.thrust["b"], stand.torque["d"]
        radius = radius or ident.rotor_radius
        fm = figure_of_merit(b, d, ident.air_density, radius)
        print(f"  stand {stand.source}: b = {b:.5g}, d = {d:.5g}, "
              f"d/b = {stand.ratio.value:.5g} m, FM (R = {radius:g} m, {how}) = {fm:.3f}"
              + _fm_flag(fm))


def _print_inertia(ident: TestbedIdentification) -> None:
    bif = ident.bifilar
    print("\nINERTIA (kg m^2)")
    print(f"  {'axis':<7}{'periods [s]':<20}{'bifilar':>10}{'report formula':>16}{'lumped':>10}")
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        periods = " ".join(f"{t:.2f}" for t in bif.periods[axis])
        print(f"  {axis:<7}{periods:<20}{bif.moments[i]:>10.4g}{bif.published[i]:>16.4g}"
              f"{ident.lumped[i]:>10.4g}")
    print("  bifilar: I = m g R^2 T^2/(4 pi^2 L); report formula: [T/(2 pi)] m g R^2/L "
          "(no square; kg m^2/s)")
    print(f"  bifilar checks: {'physical' if bif.physical else '; '.join(bif.problems)}")
    if ident.inertia_warning:
        print(f"  WARNING: {ident.inertia_warning}")


def _print_audit(findings: list[Finding]) -> None:
    print("\nREPORT AUDIT")
    for finding in findings:
        mark = "ERROR" if finding.found else "ok"
        print(f"  [{mark}] {finding.title}\n          {finding.detail}")


@run_cli
@limit_numeric_threads
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.logs or args.vehicle or args.output or args.write_effects:
        return identify_logs_command(args)
    from ..core.args import check_inputs, check_number, distinct_files  # before any work

    for radius in args.stand_radius:
        check_number("--stand-radius", radius, low=0.0, high=2.0, unit="m")
    if len(args.stand_radius) > len(args.stand):
        raise InputError(f"--stand-radius: {len(args.stand_radius)} radii for "
                         f"{len(args.stand)} --stand sweeps")
    for flag in ("stand", "force_lift", "cfd", "physical", "bifilar", "bifilar_rig"):
        value = getattr(args, flag)
        check_inputs("--" + flag.replace("_", "-"),
                     value if isinstance(value, list) else [value] if value else None)
    distinct_files({"--stand": args.stand})
    distinct_files({"--force-lift": args.force_lift})
    ident = identify_testbed(force_lift_paths=args.force_lift, cfd_path=args.cfd,
                             physical_path=args.physical, bifilar_path=args.bifilar,
                             bifilar_rig_path=args.bifilar_rig)
    findings = audit_report(ident, load_params(args.model, check=False))
    stands = [fit_thrust_stand(load_thrust_stand(p)) for p in args.stand]
    radii = stand_radii(args.stand, args.stand_radius, ident.rotor_radius)
    if args.json:
        out = identification_to_json(ident)
        out["audit"] = [f.to_json() for f in findings]
        out["thrust_stand"] = []
        for stand, (radius, how) in zip(stands, radii):
            fm = figure_of_merit(stand.thrust["b"], stand.torque["d"], ident.air_density, radius)
            out["thrust_stand"].append({**stand.to_json(), "rotor_radius_m": radius,
                                        "rotor_radius_source": how, "figure_of_merit": fm,
                                        "figure_of_merit_plausible": fm <= FM_MAX_PHYSICAL})
            if fm > FM_MAX_PHYSICAL:
                out["warnings"].append(f"{stand.source}: figure of merit {fm:.3f} > "
                                       f"{FM_MAX_PHYSICAL} (R = {radius:g} m): not physical")
        for warning in out["warnings"]:
            print(f"warning: {warning}", file=sys.stderr)
        print(json.dumps(out, indent=2, sort_keys=True))
        return 0
    _print_thrust(ident)
    _print_motor_map(ident)
    _print_drag(ident, stands, radii)
    _print_inertia(ident)
    _print_audit(findings)
    return 0


# ----------------------------------------------------------------------------- --logs
# The command-side glue of identify --logs: loading, span cutting and smoothing (logs, gap
# stages), the drag factor by the gap's instrumental-variables refit, and the written set.
# The fits themselves are pure functions in quadsim.identify.from_logs.

def _series(states):
    from ..core.frames import rotate_inverse
    from .from_logs import LogSeries

    velocity = rotate_inverse(states.quat, states.velocity) if states.pose else None
    return LogSeries(states.name, states.t, states.specific_force, states.body_rate,
                     states.body_accel, states.rotor_speed, states.command, states.vbat,
                     velocity)


def _load_states(paths: list[Path], loaded=None):
    """(FlightStates per log, notes): importer, NaN and ground/idle cut, channel checks.
    ``loaded``: the FlightLogs of ``paths`` when already read."""
    import warnings as _warnings

    from ..core.errors import QuadsimWarning
    from ..gap.residual import flight_states
    from ..logs.checks import check_log
    from ..logs.flightlog import load_log

    logs, notes = [], []
    for k, path in enumerate(paths):
        with _warnings.catch_warnings(record=True) as caught:
            _warnings.simplefilter("always", QuadsimWarning)
            log, log_notes = check_log(load_log(path) if loaded is None else loaded[k])
        notes += [f"{w.message}" for w in caught] + list(log_notes)
        if not log.has_pose:
            raise InputError(f"{path}: x..z, qw..qz: no pose; without one identify --logs "
                             "needs the IMU and motor commands at 100 Hz or finer in every "
                             "log (quadsim.identify.imu)")
        if log.accel is None:
            raise InputError(f"{path}: ax, ay, az: no accelerometer; identify --logs needs the "
                             "specific force")
        if log.rotor_speed is None and log.rotor_command is None:
            raise InputError(f"{path}: rotor_*: neither rotor speeds nor motor commands")
        logs.append(log)
    # one grid for the pooled fits: every log resampled to the slowest median step
    dt = max(float(np.median(np.diff(log.t))) for log in logs)
    return [flight_states(log, dt=dt) for log in logs], notes


def _drag_iv(states, provisional) -> tuple[float, float]:
    """d and its standard error by the gap's instrumental-variables refit (relative to the
    provisional set's d; the yaw balance is linear in d)."""
    from ..gap.diagnose import BASELINE
    from ..gap.fitting import drag_refit_iv, stack_states

    usable = [s for s in states if s.rotor_speed is not None and s.command is not None]
    if not usable:
        return float("nan"), float("nan")
    stacked = stack_states(usable)
    k = BASELINE.parameter_names.index("nominal_refit.drag")
    delta, se = drag_refit_iv(stacked, provisional, BASELINE,
                              np.zeros(len(BASELINE.parameter_names)), k)
    d0 = provisional.drag_factor
    return d0 * (1.0 + delta), d0 * se


def identify_logs_command(args) -> int:
    from ..core.args import check_inputs, check_output, distinct_files
    from ..core.files import atomic_write_text
    from .from_logs import identify_from_logs
    from .imu_logs import identify_from_imu_logs, load_checked, wants_imu_path
    from .sanity import check_mass_scale, check_swapped
    from .skeleton import load_skeleton
    from .vehicle_set import build_set, flapping_effects

    bench = [f for f in ("json", "stand", "force_lift", "cfd", "physical", "bifilar",
                         "bifilar_rig") if getattr(args, f)]
    if bench:
        raise InputError(f"--{bench[0].replace('_', '-')}: belongs to the bench-table "
                         "identification, not to --logs")
    if not (args.logs and args.vehicle and args.output):
        missing = [f for f, v in (("--logs", args.logs), ("--vehicle", args.vehicle),
                                  ("-o", args.output)) if not v]
        raise InputError(f"{missing[0]}: identify from logs needs --logs, --vehicle and -o")
    check_inputs("--logs", args.logs)
    check_inputs("--vehicle", [args.vehicle])
    distinct_files({"--logs": args.logs, "--vehicle": [args.vehicle]})
    check_output("-o", args.output, (".toml",), inputs=[args.vehicle, *args.logs])
    if args.write_effects is not None:
        check_output("--write-effects", args.write_effects, (".toml",),
                     inputs=[args.vehicle, *args.logs])
        if Path(args.write_effects).resolve() == Path(args.output).resolve():
            raise InputError(f"{args.write_effects}: --write-effects: the same file as -o")
    check_swapped(args.logs, args.vehicle)
    skeleton, data = load_skeleton(args.vehicle)
    check_mass_scale(skeleton)
    logs, notes = load_checked(args.logs)
    if wants_imu_path(logs):          # no rotor speeds or no pose: IMU + commands (.imu)
        ident, notes = identify_from_imu_logs(logs, skeleton, notes)

        def drag(provisional):
            return float("nan"), float("nan")
    else:
        states, more = _load_states(list(args.logs), logs)
        notes = [n for n in notes if n not in more] + more
        ident = identify_from_logs([_series(s) for s in states], skeleton)

        def drag(provisional):
            return _drag_iv(states, provisional)
    names = ", ".join(Path(p).name for p in args.logs)
    text, params, report = build_set(data, skeleton, ident, names, drag, args.output)
    for note in notes:
        print(f"note: {note}")
    for line in report:
        print(line)
    for warning in ident.warnings + report.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    effects = flapping_effects(ident, params.name, names) if args.write_effects else None
    atomic_write_text(args.output, text)
    print(f"wrote {args.output} ({params.name}: b = {params.thrust_factor:.5g} N s^2/rad^2, "
          f"d = {params.drag_factor:.5g} N m s^2/rad^2; passes the feasibility guards)")
    if effects is not None:
        atomic_write_text(args.write_effects, effects)
        print(f"wrote {args.write_effects} (blade_flapping on {params.name})")
    elif args.write_effects is not None:
        print(f"warning: --write-effects: {args.write_effects} not written: no blade flapping "
              "identified (above)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
