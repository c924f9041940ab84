"""Two small flight campaigns in shapes the other sources do not have, flown with
``quadsim.fly``'s own generator (:func:`quadsim.logs.generate.generate_flight`) and judged per
flight as a user types it: the per-flight verdicts of a campaign, scored against what each
flight carries.

* ``tunnel``: the ``crazyflie21`` set held at 0.5 m in 0.2 m steps at 0.3 m/s, as in a wind
  tunnel; a rotor drag (1.9e-6 kg/rad), blade flapping (9e-8 / 1.4e-7 kg m/rad) and a 50 ms
  motor lag on every flight; 250 Hz. 10 references, 3 calm flights, steady winds (1 and 2 m/s
  along x, 1.5 along y, 1.5 along x and y, each with a 0.1 m/s gust), +3 g and +5 g, rotor 2
  8 % weak.
* ``testbed``: the report's 0.84 kg "+" testbed (``physical``) on figure-8s and lissajous at
  0.8-1.2 m/s, 1.5 m high; a rotor drag (1.2e-5 kg/rad) and a 40 ms motor lag on every flight;
  200 Hz. 10 references, 3 calm flights, +60 g, a CoM offset (+10, -6 mm), rotor 3 10 % weak,
  +30/30/20 % inertia, a battery sag (rate 0.01 1/s).
* ``xquad``: PX4 SITL's jMAVSim X quad (``px4_sitl_iris``, 0.8 kg, no motor map: commands
  are speed / max_speed) on figure-8s, lissajous and steps at 0.5-1.5 m/s, 2 m high; a
  rotor drag (1e-5 kg/rad), a 30 ms motor lag and a body drag (C_d A 50 cm^2, vertical
  100 cm^2) on every flight; 100 Hz, as PX4 logs its actuator outputs. 10 references, 3 calm
  flights, +80 g, a CoM offset (+8, -5 mm), rotor 2 8 % weak, every propeller 6 % weaker
  (``thrust_factor``), +25/25/20 % inertia, a battery sag (0.004 1/s), a 2 m/s wind.

Each flight's sensors: white noise on the gyro (0.01 / 0.02 rad/s), accelerometer (0.05 /
0.1 m/s^2), rotor speeds (5 rad/s) and position (0.5 / 1 mm). The logs are written as the
flight-log CSV (``--logs full``: as generated; ``commands``: the rotor speeds cut, the pose
kept; ``imu``: the IMU, the commands and the battery only) and judged in a fresh process::

    python -m quadsim.gap --model SET --per-flight FLIGHTS... --reference REFS... \\
        --workers 1 --json OUT

A cut without rotor speeds of a set without a motor map (``xquad``) is judged against the
set ``python -m quadsim.identify --logs REFS... --vehicle SET.toml -o identified.toml``
writes from its references (``gap`` refuses such logs with that advice).

Scored: a calm flight right when ``no_significant_gap``; a change **named** when the verdict
names its effect (the wind as ``wind``, a mass as ``mass_offset`` or ``cable_payload``, a weak
rotor as ``thrust_mismatch``, the CoM as ``com_offset``, the inertia as ``inertia_error``, the
sag as ``battery_sag``), **stated** when that effect is among the verdict's readings or named
beside it; a wrong name at >= 0.9 and not tentative is **confident wrong**.

Usage (from the repository root; ~2 min to fly, ~30 s to judge each campaign)::

    python -m benchmarks.campaigns [--campaign tunnel|testbed|xquad|all] [--logs full|commands|imu]
                                   [--exact-speeds] [--out DIR]

``--exact-speeds`` logs the rotor speeds without their noise, as a simulator that logs its own
state does (the other sensors as they are).

Where these campaigns came from, what their first runs found and what was left:
CHANGELOG.md (the slow-references, ordermodel and wind-law entries) and benchmarks/README.md
("Two campaigns of quadsim.fly").
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from quadsim.effects import EffectSet, make_effect
from quadsim.logs.flightlog import write_log
from quadsim.logs.generate import generate_flight
from quadsim.logs.sensors import SensorModel
from quadsim.vehicle.params import load_params


@dataclass(frozen=True)
class Flight:
    """One flight of a campaign: its name, seed, path and speed (m/s), the effects it carries
    beyond the campaign's shared ones (``(name, {parameter: value})``, SI) and the effect a
    verdict must name (None: a calm flight)."""

    name: str
    seed: int
    path: str
    speed: float
    effects: tuple = ()
    truth: str | None = None


@dataclass(frozen=True)
class Campaign:
    """A campaign as data: the parameter set, what every flight shares, the sensors, the
    flights' height, size (m) and duration (s), and its references and judged flights."""

    params: str
    shared: tuple
    noise: dict
    rate_hz: float
    height: float
    size: float
    duration: float
    references: tuple
    flights: tuple = field(default_factory=tuple)


CAMPAIGNS = {
    "tunnel": Campaign(
        "crazyflie21",
        (("rotor_drag", {"coefficient": 1.9e-6}),
         ("blade_flapping", {"roll": 9e-8, "pitch": 1.4e-7}),
         ("motor_lag", {"time_constant": 0.05})),
        {"gyro": 0.01, "accel": 0.05, "rotor": 5.0, "position": 0.0005}, 250.0, 0.5, 0.2, 10.0,
        tuple(Flight(f"ref{s:02d}", s, "steps", 0.3) for s in range(1, 11)),
        (Flight("calm21", 21, "steps", 0.3), Flight("calm22", 22, "steps", 0.3),
         Flight("calm23", 23, "steps", 0.3),
         Flight("wind_x1", 31, "steps", 0.3,
                (("wind", {"vx": 1.0, "gust": 0.1, "seed": 31}),), "wind"),
         Flight("wind_x2", 32, "steps", 0.3,
                (("wind", {"vx": 2.0, "gust": 0.1, "seed": 32}),), "wind"),
         Flight("wind_y15", 34, "steps", 0.3,
                (("wind", {"vy": 1.5, "gust": 0.1, "seed": 34}),), "wind"),
         Flight("wind_xy15", 35, "steps", 0.3,
                (("wind", {"vx": 1.5, "vy": 1.5, "gust": 0.1, "seed": 35}),), "wind"),
         Flight("mass3", 41, "steps", 0.3, (("mass_offset", {"mass": 0.003}),), "mass"),
         Flight("mass5", 42, "steps", 0.3, (("mass_offset", {"mass": 0.005}),), "mass"),
         Flight("weak2", 43, "steps", 0.3, (("thrust_mismatch", {"rotor_2": -0.08}),),
                "thrust_mismatch"))),
    "testbed": Campaign(
        "physical",
        (("rotor_drag", {"coefficient": 1.2e-5}), ("motor_lag", {"time_constant": 0.04})),
        {"gyro": 0.02, "accel": 0.1, "rotor": 5.0, "position": 0.001}, 200.0, 1.5, 1.5, 12.0,
        tuple(Flight(f"ref{s:02d}", s, "figure8" if s % 2 else "lissajous", 0.76 + 0.04 * s)
              for s in range(1, 11)),
        (Flight("calm21", 21, "figure8", 1.0), Flight("calm22", 22, "lissajous", 0.9),
         Flight("calm23", 23, "figure8", 1.1),
         Flight("mass60", 31, "figure8", 1.0, (("mass_offset", {"mass": 0.06}),), "mass"),
         Flight("com", 32, "lissajous", 1.0, (("com_offset", {"x": 0.01, "y": -0.006}),),
                "com_offset"),
         Flight("weak3", 33, "figure8", 1.0, (("thrust_mismatch", {"rotor_3": -0.1}),),
                "thrust_mismatch"),
         Flight("inertia", 34, "lissajous", 1.0,
                (("inertia_error", {"xx": 0.3, "yy": 0.3, "zz": 0.2}),), "inertia_error"),
         Flight("sag", 35, "figure8", 1.0, (("battery_sag", {"rate": 0.01}),), "battery_sag"))),
    "xquad": Campaign(
        "px4_sitl_iris",
        (("rotor_drag", {"coefficient": 1e-5}), ("motor_lag", {"time_constant": 0.03}),
         ("body_drag", {"cd_area": 0.005, "cd_area_vertical": 0.01})),
        {"gyro": 0.01, "accel": 0.05, "rotor": 8.0, "position": 0.001}, 100.0, 2.0, 2.0, 15.0,
        tuple(Flight(f"ref{s:02d}", s, ("figure8", "lissajous", "steps")[s % 3],
                     (1.0 + 0.05 * s, 0.8 + 0.04 * s, 0.5)[s % 3]) for s in range(1, 11)),
        (Flight("calm21", 21, "figure8", 1.2), Flight("calm22", 22, "lissajous", 1.0),
         Flight("calm23", 23, "steps", 0.5),
         Flight("mass80", 31, "figure8", 1.2, (("mass_offset", {"mass": 0.08}),), "mass"),
         Flight("com", 32, "lissajous", 1.0, (("com_offset", {"x": 0.008, "y": -0.005}),),
                "com_offset"),
         Flight("weak2", 33, "figure8", 1.2, (("thrust_mismatch", {"rotor_2": -0.08}),),
                "thrust_mismatch"),
         Flight("props", 34, "lissajous", 1.0, (("thrust_factor", {"change": -0.06}),),
                "thrust_factor"),
         Flight("inertia", 35, "figure8", 1.2,
                (("inertia_error", {"xx": 0.25, "yy": 0.25, "zz": 0.2}),), "inertia_error"),
         Flight("sag", 36, "steps", 0.5, (("battery_sag", {"rate": 0.004}),), "battery_sag"),
         Flight("wind", 37, "figure8", 1.2, (("wind", {"vx": 2.0, "gust": 0.2, "seed": 37}),),
                "wind"))),
}

#: the verdict names that name each truth (a mass hangs or sits)
NAMES = {"mass": ("mass_offset", "cable_payload")}
#: the flight-log columns each ``--logs`` cut keeps (None: every column)
CUTS = {"full": None, "commands": ("rotor_speed",), "imu": ("rotor_speed", "position",
                                                          "velocity", "quat")}


def fly(campaign: Campaign, flight: Flight):
    """The log of ``flight`` (:func:`quadsim.logs.generate.generate_flight`, MuJoCo)."""
    params = load_params(campaign.params)
    effects = EffectSet(tuple(make_effect(n, **v) for n, v in campaign.shared + flight.effects))
    sensors = SensorModel(noise=dict(campaign.noise), rate=campaign.rate_hz)
    log, _ = generate_flight(params, flight.path, effects, sensors, flight.seed,
                             duration=campaign.duration, speed=flight.speed,
                             height=campaign.height, size=campaign.size)
    return log


def cut(log, logs: str):
    """``log`` with the columns the ``logs`` cut drops set to None (:data:`CUTS`)."""
    dropped = CUTS[logs]
    return log if dropped is None else dataclasses.replace(log, **{k: None for k in dropped})


def score(flight: Flight, entry: dict) -> str:
    """``right`` / ``named`` / ``stated`` / ``confident wrong`` / ``miss`` for a verdict JSON
    ``entry`` of ``flight`` (module doc)."""
    verdict, p = entry.get("verdict") or entry.get("outcome"), entry.get("probability", 0.0)
    if flight.truth is None:
        return "right" if verdict == "no_significant_gap" else (
            "confident wrong" if verdict not in ("unexplained", "refused") and p >= 0.9
            and not entry.get("tentative") else "miss")
    names = NAMES.get(flight.truth, (flight.truth,))
    parts = str(verdict).split("+")
    if any(n in parts for n in names):
        return "named"
    read = set(entry.get("readings") or []) | set(entry.get("confusable_with") or [])
    if any(n in part for part in read for n in names):
        return "stated"
    return ("confident wrong" if verdict not in ("unexplained", "refused", "no_significant_gap")
            and p >= 0.9 and not entry.get("tentative") else "miss")


def run(name: str, logs: str, out: Path, *, exact_speeds: bool = False
        ) -> list[tuple[Flight, dict, str]]:
    """Fly campaign ``name`` into ``out``, judge it as a user types it, score each flight.
    ``exact_speeds``: the rotor speeds logged without their noise (what a simulator that logs
    its own state writes; the other sensors as they are), into ``out / name / exact-LOGS``."""
    campaign = CAMPAIGNS[name]
    if exact_speeds:
        campaign = dataclasses.replace(campaign, noise={**campaign.noise, "rotor": 0.0})
    folder = out / name / (f"exact-{logs}" if exact_speeds else logs)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for flight in campaign.references + campaign.flights:
        path = folder / f"{flight.name}.csv.gz"
        if not path.exists():
            write_log(path, cut(fly(campaign, flight), logs))
        paths[flight.name] = path
    result = folder / "verdicts.json"
    model = campaign.params
    params = load_params(campaign.params)
    if CUTS[logs] is not None and params.motor_map is None:
        # no map to synthesise speeds from: the set a user writes first, from the references
        # (the refusal's own advice), and judges with
        model = str(folder / "identified.toml")
        done = subprocess.run([sys.executable, "-m", "quadsim.identify", "--logs",
                               *[str(paths[f.name]) for f in campaign.references],
                               "--vehicle", str(params.path), "-o", model],
                              capture_output=True, text=True)
        if done.returncode != 0:
            last = done.stderr.strip().splitlines()[-1:] or ["(no message)"]
            return [(f, {"outcome": "refused", "answer": last[0]}, "miss")
                    for f in campaign.flights]
    command = [sys.executable, "-m", "quadsim.gap", "--model", model, "--per-flight",
               *[str(paths[f.name]) for f in campaign.flights], "--reference",
               *[str(paths[f.name]) for f in campaign.references], "--workers", "1",
               "--json", str(result)]
    done = subprocess.run(command, capture_output=True, text=True,
                          env={**os.environ, "QUADSIM_CACHE_DIR": str(folder / "cache")})
    if done.returncode != 0:
        last = done.stderr.strip().splitlines()[-1:] or ["(no message)"]
        return [(f, {"outcome": "refused", "answer": last[0]}, "miss")
                for f in campaign.flights]
    entries = json.loads(result.read_text())["flights"]
    return [(f, e, score(f, e)) for f, e in zip(campaign.flights, entries)]


def table(name: str, logs: str, rows: list) -> str:
    """The campaign's rows as a markdown table, and its counts."""
    lines = [f"{name} ({logs})", "", "| flight | truth | verdict | p | tentative | score |",
             "|---|---|---|---:|---|---|"]
    for f, e, s in rows:
        lines.append(f"| {f.name} | {f.truth or 'none'} | {e.get('verdict') or e.get('outcome')}"
                     f" | {e.get('probability', float('nan')):.2f} | "
                     f"{'yes' if e.get('tentative') else ''} | {s} |")
    calm = [s for f, _, s in rows if f.truth is None]
    changed = [s for f, _, s in rows if f.truth is not None]
    lines += ["", f"calm clear {calm.count('right')}/{len(calm)}; changes named "
              f"{changed.count('named')}/{len(changed)}, named or stated "
              f"{changed.count('named') + changed.count('stated')}/{len(changed)}; confident "
              f"wrong {sum(s == 'confident wrong' for s in calm + changed)}"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", choices=[*CAMPAIGNS, "all"], default="all")
    parser.add_argument("--logs", choices=list(CUTS), default="full")
    parser.add_argument("--exact-speeds", action="store_true",
                        help="log the rotor speeds without their noise (a simulator's own state)")
    parser.add_argument("--out", type=Path, default=None,
                        help="folder for the flights and verdicts (default: a temporary one)")
    args = parser.parse_args(argv)
    names = list(CAMPAIGNS) if args.campaign == "all" else [args.campaign]
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        for name in names:
            rows = run(name, args.logs, out, exact_speeds=args.exact_speeds)
            label = f"{args.logs}, exact speeds" if args.exact_speeds else args.logs
            print(table(name, label, rows), end="\n\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
