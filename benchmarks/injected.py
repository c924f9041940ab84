"""Real flights with a known change written into them: the diagnosis's power and its false
alarms on real noise, real controllers and the real vehicle's unmodelled traits.

The labelled ``mixed/`` campaign has one change (a +7.4 g payload, partly on a cable); the
simulator sources have every change but not a real vehicle's noise and traits. This harness
takes real flights (the plain ``mixed/`` flights by default: no change, 9/10 clear against the
20 nominal flights) and writes into their logs what a changed vehicle flying the same
trajectory would have logged, exactly for the changes that leave the motion as it was:

* **a rigid mass at the CoM** (``mass``, kg): the vehicle of mass m + dm needs (1 + dm/m) times
  the collective thrust for the same specific force; added equally to every rotor it adds no
  roll, pitch or yaw torque (a symmetric X: the hubs' lever arms and the spins cancel), so
  ``Omega_i'^2 = Omega_i^2 + (dm / m) sum_j Omega_j^2 / R``. The point mass at the CoM adds no
  inertia. Left out: the drag's share of the thrust (the extra thrust scales the rotors', not
  the air's: an error of dm/m times the drag, ~0.1 % of the added thrust at 1 m/s).
* **one weaker propeller** (``rotor``, (i, e)): rotor i's thrust and drag torque per Omega^2 are
  (1 + e) times the set's, so the same motion needs ``Omega_i' = Omega_i / sqrt(1 + e)``
  (thrust and drag torque the same as logged).

In both, the motors are read as speed-controlled (a command asks for a speed, the set's map),
so the commands move with the speeds: each rotor's steady speed change, led by the map's time
constant (the command model lags by it), is turned into a command change through the set's
map at the logged battery voltage (:func:`commands_for`). A log without commands keeps none.

Each injected log is written as a flight-log CSV into a temporary folder and judged as a user
types it, in a fresh process with a fresh references' cache::

    python -m quadsim.gap --model crazyflie21 --per-flight <the injected logs> \\
        --reference <the 20 nominal flights> --workers 1 --json OUT

Scored (:func:`score`): a flight as logged (``none``) right when ``no_significant_gap``; a mass
right when the verdict names ``mass_offset`` or ``cable_payload`` with a total within
``max(MASS_TOLERANCE_KG, MASS_TOLERANCE_SHARE x dm)`` of dm; a propeller right when it names
``thrust_mismatch`` of rotor i within ``max(0.02, 0.5 |e|)`` of e. A wrong answer not
``tentative`` is counted apart (a confident wrong name).

Usage (needs ``../shared/data``; ~1 s CPU per judged flight plus the references' ~15 s)::

    python -m benchmarks.injected                          # the plain mixed flights, default grid
    python -m benchmarks.injected --masses 0.001 0.002 0.004 --rotor-changes -0.05 --out inj.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "crazyflie21_brushless"

#: a mass reading is right within the larger of these of the injected mass: 0.5 g is the
#: size of the reading's own interval on a real 6 s flight (+-0.2-0.4 g on the mixed
#: payloads) with margin; 25 % leaves room for a rigid mass read partly as a payload
MASS_TOLERANCE_KG = 0.0005
MASS_TOLERANCE_SHARE = 0.25
#: a propeller reading is right within the larger of these of the injected change
ROTOR_TOLERANCE = 0.02
ROTOR_TOLERANCE_SHARE = 0.5


@dataclass(frozen=True)
class Change:
    """One change written into a log: ``kind`` "none", "mass" (``value`` kg at the CoM) or
    "rotor" (``rotor`` 1-based, ``value`` the relative change e of its thrust and drag per
    Omega^2)."""

    kind: str
    value: float = 0.0
    rotor: int = 0

    @property
    def label(self) -> str:
        if self.kind == "mass":
            return f"mass {self.value * 1e3:+.1f} g"
        if self.kind == "rotor":
            return f"rotor {self.rotor} {self.value * 100:+.0f} %"
        return "none"


def speeds_with_mass(speed: np.ndarray, params, added_kg: float) -> np.ndarray:
    """(N, R) rad/s: ``speed`` with the collective thrust scaled by 1 + dm/m, added equally to
    every rotor (module doc): ``Omega_i'^2 = Omega_i^2 + (dm/m) sum_j Omega_j^2 / R``."""
    speed = np.asarray(speed, dtype=float)
    square = np.square(speed)
    extra = (added_kg / params.mass) * square.sum(axis=1, keepdims=True) / speed.shape[1]
    return np.sqrt(square + extra)


def speeds_with_rotor(speed: np.ndarray, rotor: int, change: float) -> np.ndarray:
    """(N, R) rad/s: ``speed`` with rotor ``rotor`` (1-based) at ``1 / sqrt(1 + change)`` of
    its speed, the thrust and drag torque of a propeller with (1 + change) times the set's
    factors the same as logged."""
    out = np.array(speed, dtype=float)
    out[:, rotor - 1] = out[:, rotor - 1] / np.sqrt(1.0 + change)
    return out


def commands_for(log, params, speed: np.ndarray) -> np.ndarray | None:
    """(N, R) the log's commands moved with its speeds to ``speed`` (module doc): each rotor's
    steady change ``d = (speed - logged) + tau d/dt (speed - logged)`` (``tau`` the map's time
    constant) taken through the set's map at the logged battery voltage (its voltage law),
    ``c' = map_i^-1(map_i(c) + d / (1 + g (v - v_ref)))``; without a map, the commands are
    ``speed / max_speed`` and move by ``d / max_speed``. None when the log has no commands."""
    if log.rotor_command is None:
        return None
    delta = np.asarray(speed, float) - np.asarray(log.rotor_speed, float)
    mm = params.motor_map
    tau = 0.0 if mm is None else float(mm.time_constant)
    if tau > 0:
        delta = delta + tau * np.gradient(delta, log.t, axis=0)
    command = np.asarray(log.rotor_command, float)
    if mm is None:
        return command + delta / float(params.max_speed)
    if mm.duty_voltage is not None:
        raise ValueError(f"{params.name}: motor_map.duty_voltage: a duty-cycle map is not "
                         "inverted here (give a set whose map is in speed per command)")
    if log.vbat is not None and mm.reference_voltage is not None and mm.voltage_gain:
        delta = delta / (1.0 + mm.voltage_gain
                         * (np.asarray(log.vbat, float) - mm.reference_voltage))[:, None]
    steady = mm.speed_of(command) + delta
    return np.stack([np.interp(steady[:, i], mm.speed[i], mm.command,
                               left=np.nan, right=np.nan)
                     for i in range(steady.shape[1])], -1)


def injected(log, params, change: Change):
    """``log`` as the vehicle with ``change`` would have logged the same flight (module doc);
    ``log`` itself for "none". Raises ValueError where a command leaves the map's range."""
    if change.kind == "none":
        return log
    if log.rotor_speed is None:
        raise ValueError(f"{log.path}: rotor_1..rotor_N: the change is written into the rotor "
                         "speeds; this log has none")
    if change.kind == "mass":
        speed = speeds_with_mass(log.rotor_speed, params, change.value)
    elif change.kind == "rotor":
        speed = speeds_with_rotor(log.rotor_speed, change.rotor, change.value)
    else:
        raise ValueError(f"kind: {change.kind!r} (expected none, mass or rotor)")
    command = commands_for(log, params, speed)
    if command is not None and not np.isfinite(command).all():
        raise ValueError(f"{log.path}: cmd_*: the changed speeds leave the motor map's range")
    return replace(log, rotor_speed=speed, rotor_command=command)


def grid(masses, rotor_changes, flights: int) -> list[list[Change]]:
    """The changes of each of ``flights`` flights: every flight as logged, with each mass,
    and with each rotor change on rotor 1 + (flight index mod 4)."""
    return [[Change("none")] + [Change("mass", m) for m in masses]
            + [Change("rotor", e, 1 + k % 4) for e in rotor_changes] for k in range(flights)]


def score(change: Change, flight: dict) -> dict:
    """Whether the answer ``flight`` (one entry of the ``quadsim.gap/3`` per-flight JSON) is
    right for ``change`` (module doc), and whether it is a confident wrong name."""
    outcome, verdict = str(flight.get("outcome")), str(flight.get("verdict") or "")
    params = flight.get("params") or {}
    names = verdict.split("+")
    reading = None
    if change.kind == "none":
        right = outcome == "no_significant_gap"
    elif change.kind == "mass":
        masses = [float(v) for k, v in params.items() if k.endswith(".mass")]
        reading = sum(masses) if masses else None
        tolerance = max(MASS_TOLERANCE_KG, MASS_TOLERANCE_SHARE * abs(change.value))
        right = (outcome == "effect" and bool({"mass_offset", "cable_payload"} & set(names))
                 and reading is not None and abs(reading - change.value) <= tolerance)
    else:
        reading = params.get(f"thrust_mismatch.rotor_{change.rotor}")
        tolerance = max(ROTOR_TOLERANCE, ROTOR_TOLERANCE_SHARE * abs(change.value))
        right = (outcome == "effect" and "thrust_mismatch" in names and reading is not None
                 and abs(float(reading) - change.value) <= tolerance)
    confident_wrong = (not right and outcome == "effect" and not flight.get("tentative"))
    return {"change": change.label, "verdict": verdict, "outcome": outcome,
            "probability": flight.get("probability"), "tentative": bool(flight.get("tentative")),
            "reading": reading, "right": bool(right), "confident_wrong": bool(confident_wrong),
            "stated": list(flight.get("readings") or ()),
            "posterior": [{"name": r.get("name"), "probability": r.get("probability"),
                           "log_evidence": r.get("log_evidence"), "params": r.get("params")}
                          for r in (flight.get("posterior") or ())[:6]]}


def _write(logs_changes, folder: Path) -> list[Path]:
    from quadsim.logs.flightlog import write_log

    out = []
    for k, (log, change) in enumerate(logs_changes):
        stem = Path(str(log.path)).name.split(".")[0]
        tag = change.label.replace(" ", "_").replace("%", "pc").replace("+", "p")
        out.append(write_log(folder / f"{k:03d}_{stem}_{tag}.csv.gz", log))
    return out


def judge(paths: list[Path], references: list[Path], out: Path, model: str) -> dict:
    """The per-flight JSON of ``paths`` against ``references`` (a fresh process and
    references' cache, one numeric thread, as a user's run)."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               QUADSIM_CACHE_DIR=tempfile.mkdtemp(prefix="qinj_"))
    cmd = [sys.executable, "-m", "quadsim.gap", "--model", model, "--per-flight",
           *map(str, paths), "--reference", *map(str, references), "--workers", "1",
           "--json", str(out)]
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return json.loads(out.read_text())


def _plain_mixed(data: Path) -> list[Path]:
    labels = json.loads((data / "mixed_labels.json").read_text())["flights"]
    return sorted(data / "mixed" / name for name, entry in labels.items()
                  if entry["label"] == "none")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.injected",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--flights", type=Path, nargs="+",
                    help="the flights to change (default: the plain mixed/ flights)")
    ap.add_argument("--reference", type=Path, nargs="+",
                    help="the reference flights (default: the 20 nominal/ flights)")
    ap.add_argument("--model", default="crazyflie21")
    ap.add_argument("--masses", type=float, nargs="*", default=[0.001, 0.002, 0.004],
                    help="rigid masses at the CoM, kg (default 1, 2, 4 g)")
    ap.add_argument("--rotor-changes", type=float, nargs="*", default=[-0.05, -0.10],
                    help="one propeller's relative thrust change, each on rotor 1 + (flight "
                         "index mod 4) (default -5 %%, -10 %%)")
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--out", type=Path, help="every answer and the scores as JSON")
    args = ap.parse_args(argv)
    flights = args.flights or _plain_mixed(args.data)
    references = args.reference or sorted((args.data / "nominal").glob("flight_*.csv.gz"))
    if not flights or not references:
        print(f"error: {args.data}: no flights found (give --flights and --reference)",
              file=sys.stderr)
        return 2
    from quadsim.logs.flightlog import load_log
    from quadsim.vehicle.params import load_params

    params = load_params(args.model)
    logs = [load_log(p, warn=False) for p in flights]
    pairs = [(injected(log, params, c), c)
             for log, changes in zip(logs, grid(args.masses, args.rotor_changes, len(logs)))
             for c in changes]
    with tempfile.TemporaryDirectory(prefix="qinj_logs_") as folder:
        paths = _write(pairs, Path(folder))
        result = judge(paths, references, Path(folder) / "result.json", args.model)
    answered = {Path(str(f["file"])).name: f for f in result["flights"]}
    answers = [dict(score(change, answered[path.name]), flight=Path(str(log.path)).name)
               for (log, change), path in zip(pairs, paths)]
    by: dict[str, list] = {}
    for (_, change), answer in zip(pairs, answers):
        key = (f"rotor {change.value * 100:+.0f} %" if change.kind == "rotor"
               else change.label)
        by.setdefault(key, []).append(answer)
    print(f"{len(flights)} flights x {len(answers) // len(flights)} changes against "
          f"{len(references)} references ({args.model})")
    for key, rows in by.items():
        right = sum(r["right"] for r in rows)
        wrong = sum(r["confident_wrong"] for r in rows)
        readings = [r["reading"] for r in rows if r["reading"] is not None]
        print(f"  {key:16s} right {right}/{len(rows)}, confident wrong {wrong}"
              + (f"; readings {min(readings):+.4g}..{max(readings):+.4g}" if readings else ""))
    if args.out:
        args.out.write_text(json.dumps({"flights": [str(p) for p in flights],
                                        "references": [str(p) for p in references],
                                        "answers": answers}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
