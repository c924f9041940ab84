"""Write models/crazyflie21.toml: the Crazyflie 2.1 Brushless parameter set.

Facts (mass, rotor layout, spin, torque/thrust ratio, rotor radius, inertia range) come from
the data README of the crazyflie21_brushless flights; the thrust factor b and the
command -> speed map are identified here from the *nominal* flights only (never from
``mixed/``):

* b: least squares through the origin of the body-z force balance
  ``m * f_z = b * sum_i Omega_i^2`` over every sample of every nominal flight, with the
  accelerometer specific force and rotor speeds smoothed by the same Savitzky–Golay filter
  (quadsim.gap.residual). Its spread is the standard deviation of the per-flight estimates.
* motor map: per-rotor straight line Omega = a + k * cmd fitted on the same samples,
  stored at cmd = 0 and 1 (it is only trusted inside the flown range, about 0.3-0.5).
* d = 0.006 m * b (README: torque/thrust ratio of Crazyflie 2.x propellers).

Not ``python -m quadsim.identify --logs``: that command identifies d (yaw balance,
instrumental variables), Ixx, Iyy and a lagged, voltage-dependent motor map from the logs.
On these flights it gives the same b (3.703e-8 N s^2/rad^2) but d = 0.00148 m x b, a hover
figure of merit of 1.7, which the vehicle guards refuse (nothing written); this set keeps
the README's facts instead (``python -m quadsim.identify --logs
../shared/data/crazyflie21_brushless/nominal/flight_*.csv.gz --vehicle SKELETON.toml -o
cf.toml``, the skeleton being this file without thrust_factor, drag_factor, max_speed and
[motor_map]).

Usage::

    python scripts/identify_crazyflie.py [--data ../shared/data/crazyflie21_brushless]
                                         [--out models/crazyflie21.toml]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from quadsim.core.errors import InputError, QuadsimWarning, run_cli  # noqa: E402
from quadsim.core.files import atomic_write_text  # noqa: E402
from quadsim.gap.residual import flight_states  # noqa: E402
from quadsim.logs.flightlog import load_log  # noqa: E402

MASS = 0.037            # kg, README: total mass with battery
HUB = 0.0354            # m, README: x and y hub offsets (0.050 m from the centre)
TORQUE_RATIO = 0.006    # m, README: torque/thrust ratio (firmware value, brushed CF 2.x)
RADIUS = 0.0275         # m, README: rotor radius 0.025-0.03 m, midpoint
INERTIA = (2.05e-5, 2.05e-5, 3.05e-5)  # kg m^2, README literature range midpoints
README = "crazyflie21_brushless data README"


def identify(nominal: list[Path]) -> dict:
    """b (N s^2/rad^2), its per-flight spread, the per-rotor linear motor map, speed range."""
    numerator = denominator = 0.0
    per_flight, rows_cmd, rows_speed, peak = [], [], [], 0.0
    for path in nominal:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", QuadsimWarning)
            states = flight_states(load_log(path))
        omega2 = np.square(states.rotor_speed).sum(1)
        force_z = MASS * states.specific_force[:, 2]
        numerator += float(force_z @ omega2)
        denominator += float(omega2 @ omega2)
        per_flight.append(float(force_z @ omega2) / float(omega2 @ omega2))
        rows_cmd.append(states.command)
        rows_speed.append(states.rotor_speed)
        peak = max(peak, float(states.rotor_speed.max()))
    command, speed = np.concatenate(rows_cmd), np.concatenate(rows_speed)
    lines = []
    for i in range(speed.shape[1]):
        slope, intercept = np.polyfit(command[:, i], speed[:, i], 1)
        lines.append((intercept, intercept + slope))
    return {"b": numerator / denominator, "b_std": float(np.std(per_flight, ddof=1)),
            "flights": len(per_flight), "map": lines, "peak": peak,
            "cmd_range": (float(command.min()), float(command.max()))}


def render(fit: dict) -> str:
    b, d = fit["b"], TORQUE_RATIO * fit["b"]
    src_b = (f"identified by scripts/identify_crazyflie.py: body-z force balance m*f_z = "
             f"b*sum(Omega^2), accelerometer, {fit['flights']} nominal flights; per-flight "
             f"std {fit['b_std']:.2e}")
    lo, hi = fit["cmd_range"]
    src_map = (f"scripts/identify_crazyflie.py: per-rotor line fit on nominal flights "
               f"(flown cmd {lo:.2f}-{hi:.2f}; outside that an extrapolation)")
    speeds = ", ".join(f"[{a:.1f}, {e:.1f}]" for a, e in fit["map"])
    rotors = [("1", HUB, -HUB, "ccw", "front-right"), ("2", -HUB, -HUB, "cw", "rear-right"),
              ("3", -HUB, HUB, "ccw", "rear-left"), ("4", HUB, HUB, "cw", "front-left")]
    rotor_text = "".join(
        f'\n[[rotor]]\nname = "{n}"\nposition = {{ value = [{x}, {y}, 0.0], unit = "m", '
        f'source = "{README}: motor {n} {where}, hub offsets +-0.0354 m (+-5 %)" }}\n'
        f'spin = "{s}"\n' for n, x, y, s, where in rotors)
    ixx, iyy, izz = INERTIA
    inertia = f"[[{ixx}, 0.0, 0.0], [0.0, {iyy}, 0.0], [0.0, 0.0, {izz}]]"
    src_inertia = (f"{README}: midpoints of the Crazyflie 2.x literature range "
                   "(not measured for this vehicle)")
    src_d = f"{README}: torque/thrust ratio 0.006 m times the identified b"
    max_speed = f"{max(2750.0, fit['peak']):.1f}"
    src_max = ("thrust_stand/pwm_rpm_log.csv: rpm4 peak 26304 rpm "
               "(rpm1-3 unreliable per its authors)")
    src_radius = f"{README}: rotor radius 0.025-0.03 m, midpoint"
    return f'''# Parameter set "crazyflie21": Crazyflie 2.1 Brushless as flown in nominal/ flights.
# Written by scripts/identify_crazyflie.py (do not edit by hand; rerun the script).
schema = "quadsim.vehicle.params/1"
name = "crazyflie21"
description = "Crazyflie 2.1 Brushless, 37 g quad-X; b identified from the nominal flights"

[body]
mass = {{ value = {MASS}, unit = "kg", source = "{README}: total mass with battery" }}
com = {{ value = [0.0, 0.0, 0.0], unit = "m", source = "assumed: symmetric frame" }}
inertia = {{ value = {inertia}, unit = "kg m^2", source = "{src_inertia}" }}

[rotors]
thrust_factor = {{ value = {b:.5g}, unit = "N s^2/rad^2", source = "{src_b}" }}
drag_factor = {{ value = {d:.5g}, unit = "N m s^2/rad^2", source = "{src_d}" }}
max_speed = {{ value = {max_speed}, unit = "rad/s", source = "{src_max}" }}
radius = {{ value = {RADIUS}, unit = "m", source = "{src_radius}" }}

[motor_map]
command_unit = "1"
command = {{ value = [0.0, 1.0], unit = "1", source = "{src_map}" }}
speed = {{ value = [{speeds}], unit = "rad/s", source = "{src_map}" }}
{rotor_text}'''


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    root = Path(__file__).resolve().parent.parent
    parser.add_argument("--data", type=Path,
                        default=root.parent / "shared/data/crazyflie21_brushless",
                        help="folder holding nominal/flight_*.csv.gz")
    parser.add_argument("--out", type=Path, default=root / "models/crazyflie21.toml")
    args = parser.parse_args(argv)
    nominal = sorted((args.data / "nominal").glob("flight_*.csv*"))
    if not nominal:
        raise InputError(f"{args.data / 'nominal'}: no flight_*.csv(.gz) files")
    fit = identify(nominal)
    atomic_write_text(args.out, render(fit))
    print(f"b = {fit['b']:.5g} N s^2/rad^2 (per-flight std {fit['b_std']:.2g}, "
          f"{fit['flights']} flights) -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
