"""Real flights with a known change written into them: the diagnosis's power and its false
alarms on real noise, real controllers and the real vehicle's unmodelled traits.

The labelled ``mixed/`` campaign has one change (a +7.4 g payload, partly on a cable); the
simulator sources have every change but not a real vehicle's noise and traits. This harness
takes real flights (the plain ``mixed/`` flights by default: no change, 9/10 clear against the
20 nominal flights) and writes into their logs what a changed vehicle flying the same
trajectory would have logged, exactly for the changes that leave the motion as it was:

* **a rigid mass at the CoM** (``mass``, kg): the vehicle of mass m + dm needs (1 + dm/m) times
  the collective thrust for the same specific force, added without a roll, pitch or yaw torque
  (:func:`speeds_with_mass`: on a symmetric X every rotor's thrust rises by the same amount).
  The point mass at the CoM adds no inertia. Left out: the drag's share of the force (the
  extra thrust scales the rotors', not the air's: an error of dm/m times the drag, ~0.1 % of
  the added thrust at 1 m/s).
* **one weaker propeller** (``rotor``, (i, e)): rotor i's thrust and drag torque per Omega^2 are
  (1 + e) times the set's, so the same motion needs ``Omega_i' = Omega_i / sqrt(1 + e)``
  (thrust and drag torque the same as logged); **every propeller** so (``propeller``, e).
* **a rotor-speed logging delay** (``delay``, s): the rotor speeds logged that much later
  (:func:`speeds_later`; the motion and the commands as they were).

The motors are read as speed-controlled (a command asks for a speed, the set's map), so the
commands move with the speeds: each rotor's steady speed change, led by the map's time
constant (the command model lags by it), is turned into a command change through the set's
map at the logged battery voltage (:func:`commands_for`). A log without commands keeps none.

Each injected log is written as a flight-log CSV into a temporary folder and judged as a user
types it, in a fresh process with a fresh references' cache::

    python -m quadsim.gap --model crazyflie21 --per-flight <the injected logs> \\
        --reference <the 20 nominal flights> --workers 1 --json OUT

``--mode held-out`` takes the flights in threes (two training flights and a held-out one, each
with the same change) and judges each three in its own run (``python -m quadsim.gap --model
M A B --holdout C --reference ...``), the references' stage computed once (one cache folder
for the harness run); its verdict is scored as a per-flight answer.

Scored (:func:`score`): a flight as logged (``none``) right when ``no_significant_gap``; a
change **named** when the verdict names it at its size (:data:`EXPECTED`: a mass as
``mass_offset`` or ``cable_payload``, a propeller as ``thrust_mismatch`` of its rotor, a set as
``thrust_factor``, a delay as ``signal_delay``), **stated** when that reading is the name or is
stated beside it (a collinear reading the answer gives with its size). A wrong name not
``tentative`` is counted apart (a confident wrong name).

Usage (needs ``../shared/data``; ~1 s CPU per judged flight plus the references' ~15 s)::

    python -m benchmarks.injected                          # the plain mixed flights, default grid
    python -m benchmarks.injected --masses 0.001 0.002 0.004 --rotor-changes -0.05 --out inj.json
    python -m benchmarks.injected --logs commands          # every log cut to IMU, pose, commands
    python -m benchmarks.injected --mode held-out          # 2 training + 1 held out, each changed
    python -m benchmarks.injected --shipped --logs commands  # the set's shipped reference
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

#: a mass reading is right within the larger of these of the injected mass (:data:`EXPECTED`)
MASS_TOLERANCE_KG = 0.0005
MASS_TOLERANCE_SHARE = 0.25
#: a propeller reading is right within the larger of these of the injected change
ROTOR_TOLERANCE = 0.02
ROTOR_TOLERANCE_SHARE = 0.5


@dataclass(frozen=True)
class Change:
    """One change written into a log: ``kind`` "none", "mass" (``value`` kg at the CoM),
    "rotor" (``rotor`` 1-based, ``value`` the relative change e of its thrust and drag per
    Omega^2), "propeller" (every rotor's, ``value`` e) or "delay" (the rotor speeds logged
    ``value`` s later)."""

    kind: str
    value: float = 0.0
    rotor: int = 0

    @property
    def label(self) -> str:
        if self.kind == "mass":
            return f"mass {self.value * 1e3:+.1f} g"
        if self.kind == "rotor":
            return f"rotor {self.rotor} {self.value * 100:+.0f} %"
        if self.kind == "propeller":
            return f"propellers {self.value * 100:+.0f} %"
        if self.kind == "delay":
            return f"rotor delay {self.value * 1e3:+.0f} ms"
        return "none"


def speeds_with_mass(speed: np.ndarray, params, added_kg: float) -> np.ndarray:
    """(N, R) rad/s: ``speed`` with the body-z thrust scaled by 1 + dm/m and no roll, pitch or
    yaw torque added: ``Omega'^2 = Omega^2 + (dm/m) F_z(Omega) s``, with ``F_z`` the rows of
    :func:`quadsim.vehicle.rotors.allocation_matrix` for body-z force and ``s`` the
    least-norm squared speeds that give a unit of it and no torque (the pseudo-inverse of its
    force-z and torque rows; on a symmetric X, 1 / (4 b) on every rotor: each rotor's thrust
    up by the same amount). ValueError where the layout cannot add thrust without torque."""
    from quadsim.vehicle.rotors import allocation_matrix

    speed = np.asarray(speed, dtype=float)
    rows = allocation_matrix(params)[2:6]
    share = np.linalg.pinv(rows)[:, 0]
    if not np.allclose(rows @ share, [1.0, 0.0, 0.0, 0.0], atol=1e-9):
        raise ValueError(f"{params.name}: rotors: the layout cannot add thrust without a torque")
    square = np.square(speed)
    extra = (added_kg / params.mass) * (square @ rows[0])[:, None] * share[None, :]
    return np.sqrt(square + extra)


def speeds_with_rotor(speed: np.ndarray, rotor: int, change: float) -> np.ndarray:
    """(N, R) rad/s: ``speed`` with rotor ``rotor`` (1-based) at ``1 / sqrt(1 + change)`` of
    its speed, the thrust and drag torque of a propeller with (1 + change) times the set's
    factors the same as logged."""
    out = np.array(speed, dtype=float)
    out[:, rotor - 1] = out[:, rotor - 1] / np.sqrt(1.0 + change)
    return out


def speeds_later(log, delay_s: float) -> np.ndarray:
    """(N, R) rad/s: the log's rotor speeds as logged ``delay_s`` s later, ``Omega'(t) =
    Omega(t - delay_s)`` (linear interpolation, the first sample held before the log's
    start), each airborne stretch alone (nothing is read across a ground span)."""
    out = np.array(log.rotor_speed, dtype=float)
    bounds = [0, *log.segments, len(log.t)]
    for a, b in zip(bounds[:-1], bounds[1:]):
        t = log.t[a:b]
        out[a:b] = np.stack([np.interp(t - delay_s, t, log.rotor_speed[a:b, i])
                             for i in range(out.shape[1])], -1)
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
    if tau > 0:         # each airborne stretch alone (no derivative across a ground span)
        bounds = [0, *log.segments, len(log.t)]
        delta = delta + tau * np.concatenate(
            [np.gradient(delta[a:b], log.t[a:b], axis=0) if b - a > 1 else 0.0 * delta[a:b]
             for a, b in zip(bounds[:-1], bounds[1:])])
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
    elif change.kind == "propeller":
        speed = np.asarray(log.rotor_speed, float) / np.sqrt(1.0 + change.value)
    elif change.kind == "delay":       # a logging delay: the commands stay as sent
        return replace(log, rotor_speed=speeds_later(log, change.value))
    else:
        raise ValueError(f"kind: {change.kind!r} (expected none, mass, rotor, propeller or "
                         "delay)")
    command = commands_for(log, params, speed)
    if command is not None and not np.isfinite(command).all():
        raise ValueError(f"{log.path}: cmd_*: the changed speeds leave the motor map's range")
    return replace(log, rotor_speed=speed, rotor_command=command)


def grid(changes: dict, flights: int, rotors: int = 4) -> list[list[Change]]:
    """The changes of each of ``flights`` flights: every flight as logged, then for each kind
    of ``changes`` ({kind: values}) each value ("rotor" on rotor 1 + (flight index mod
    ``rotors``))."""
    return [[Change("none")] + [Change(kind, v, 1 + k % rotors if kind == "rotor" else 0)
                                for kind, values in changes.items() for v in values]
            for k in range(flights)]


#: per kind of change: the readings that name it, and the tolerance of its size (SI) as
#: (floor, share of the change): a mass 0.5 g (its interval on a real 6 s flight, +-0.2-0.4 g
#: on the mixed payloads, with margin) or 25 % (a rigid mass read partly on a cable); a
#: propeller's thrust 2 points or half the change; a rotor timing 2 ms (its interval on a
#: real flight, +-1-5 ms) or half the change
EXPECTED = {"mass": (("mass_offset", "cable_payload"), MASS_TOLERANCE_KG, MASS_TOLERANCE_SHARE),
            "rotor": (("thrust_mismatch",), ROTOR_TOLERANCE, ROTOR_TOLERANCE_SHARE),
            "propeller": (("thrust_factor",), ROTOR_TOLERANCE, ROTOR_TOLERANCE_SHARE),
            "delay": (("signal_delay",), 0.002, 0.5)}


def _size(change: Change, params: dict) -> float | None:
    """The reading's size of ``change`` in ``params`` (a ``quadsim.gap/3`` reading's; None
    where it holds none): the masses summed, rotor i's thrust change, the thrust factor's
    change or the rotor delay (s)."""
    if change.kind == "mass":
        masses = [float(v) for k, v in params.items() if k.endswith(".mass")]
        return sum(masses) if masses else None
    key = {"rotor": f"thrust_mismatch.rotor_{change.rotor}",
           "propeller": "thrust_factor.change", "delay": "delay.rotor"}.get(change.kind)
    return None if key not in params else float(params[key])


def _is_change(change: Change, name: str, params: dict) -> bool:
    """Whether a reading ``name`` with ``params`` is ``change`` at its size (:data:`EXPECTED`)."""
    if change.kind not in EXPECTED:
        return False
    names, floor, share = EXPECTED[change.kind]
    size = _size(change, params)
    return (bool(set(names) & set(name.split("+"))) and size is not None
            and abs(size - change.value) <= max(floor, share * abs(change.value)))


def score(change: Change, flight: dict) -> dict:
    """Whether the answer ``flight`` (one entry of the ``quadsim.gap/3`` per-flight JSON) is
    right for ``change`` (module doc): named, stated (named, or stated beside the name), a
    confident wrong name; with the answer's readings and its posterior's first six."""
    outcome, verdict = str(flight.get("outcome")), str(flight.get("verdict") or "")
    params = flight.get("params") or {}
    if change.kind == "none":
        right, reading = outcome == "no_significant_gap", None
    else:
        right = outcome == "effect" and _is_change(change, verdict, params)
        reading = _size(change, params)
    stated = right or (outcome == "effect" and any(
        _is_change(change, str(r.get("name")), r.get("params") or {})
        for r in (flight.get("posterior") or ())
        if r.get("name") in set(flight.get("readings") or ())))
    confident_wrong = (not right and outcome == "effect" and not flight.get("tentative"))
    return {"change": change.label, "verdict": verdict, "outcome": outcome,
            "probability": flight.get("probability"),
            "probability_within_library": flight.get("probability_within_library"),
            "tentative": bool(flight.get("tentative")),
            "reading": reading, "right": bool(right), "stated": bool(stated),
            "confident_wrong": bool(confident_wrong),
            "readings": list(flight.get("readings") or ()),
            "posterior": [{"name": r.get("name"), "probability": r.get("probability"),
                           "log_evidence": r.get("log_evidence"), "params": r.get("params")}
                          for r in (flight.get("posterior") or ())[:6]]}


def _write(logs_changes, folder: Path) -> list[Path]:
    """Each (log, change) written as a flight-log CSV into ``folder`` (made), named by the
    folder, the log's file and the change (unique across the run's folders)."""
    from quadsim.logs.flightlog import write_log

    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for log, change in logs_changes:
        stem = Path(str(log.path)).name.split(".")[0]
        tag = change.label.replace(" ", "_").replace("%", "pc").replace("+", "p")
        out.append(write_log(folder / f"{folder.name}_{stem}_{tag}.csv.gz", log))
    return out


def _gap(args: list[str], out: Path, cache: str | None = None) -> dict:
    """The JSON of ``python -m quadsim.gap ARGS --workers 1 --json OUT`` in a fresh process,
    one numeric thread, as a user's run; ``cache``: its references' cache folder (default a
    fresh one). RuntimeError with quadsim's last stderr line where it exits non-zero."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               QUADSIM_CACHE_DIR=cache or tempfile.mkdtemp(prefix="qinj_"))
    cmd = [sys.executable, "-m", "quadsim.gap", *args, "--workers", "1", "--json", str(out)]
    done = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                          text=True)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise RuntimeError(f"python -m quadsim.gap exited {done.returncode}: {last}")
    return json.loads(out.read_text())


def judge(paths: list[Path], references: list[Path], out: Path, model: str) -> dict:
    """The per-flight JSON of ``paths`` against ``references`` (:func:`_gap`)."""
    return _gap(["--model", model, "--per-flight", *map(str, paths),
                 *_against(references)], out)


def _against(references: list[Path]) -> list[str]:
    """``--reference`` and the references' files; none: the set's shipped reference."""
    return ["--reference", *map(str, references)] if references else []


def judge_held_out(train: list[Path], held: Path, references: list[Path], out: Path,
                   model: str, cache: str) -> dict:
    """The held-out verdict (JSON ``verdict``) of ``train`` with ``held`` held out against
    ``references`` (:func:`_gap`; ``cache`` shared by the runs of one harness run: the
    references' stage is computed once), as a per-flight entry (``verdict`` its ``effect``)."""
    result = _gap(["--model", model, *map(str, train), "--holdout", str(held),
                   *_against(references)], out, cache)
    verdict = dict(result["verdict"])
    return dict(verdict, verdict=verdict.get("effect"))


def _without_commands(name: str) -> bool:
    """``--logs speeds``: every column but the commands (``cmd_*``)."""
    return not name.startswith("cmd_")


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
    ap.add_argument("--model", default="crazyflie21",
                    help="the parameter set (name or TOML; default crazyflie21)")
    ap.add_argument("--masses", type=float, nargs="*", default=[0.001, 0.002, 0.004],
                    help="rigid masses at the CoM, kg (default 1, 2, 4 g)")
    ap.add_argument("--rotor-changes", type=float, nargs="*", default=[-0.05, -0.10],
                    help="one propeller's relative thrust change, each on rotor 1 + (flight "
                         "index mod the rotor count) (default -5 %%, -10 %%)")
    ap.add_argument("--propeller-changes", type=float, nargs="*", default=[-0.08],
                    help="every propeller's relative thrust change (default -8 %%)")
    ap.add_argument("--delays", type=float, nargs="*", default=[0.01],
                    help="rotor speeds logged this much later, s (default 10 ms)")
    ap.add_argument("--logs", choices=("as-logged", "commands", "imu", "attitude", "speeds"),
                    default="as-logged",
                    help="cut every log (judged and references) to what a user may have, as "
                         "benchmarks.reference_subsets --logs does (commands: no rotor "
                         "speeds; imu: no pose and no rotor speeds; attitude: imu with the "
                         "attitude); speeds: no commands (no rotor channel: the change read "
                         "from the wrench alone)")
    ap.add_argument("--data", type=Path, default=DATA,
                    help="the crazyflie21_brushless folder of the shared data (default "
                         "../shared/data/crazyflie21_brushless beside the repository)")
    ap.add_argument("--shipped", action="store_true",
                    help="judge against the parameter set's shipped reference (no "
                         "--reference given to quadsim.gap: for crazyflie21 its own 20 "
                         "nominal flights, the commands-only file for logs without speeds)")
    ap.add_argument("--mode", choices=("per-flight", "held-out"), default="per-flight",
                    help="per-flight (default): each changed log judged against the "
                         "references; held-out: the flights in threes (2 training, the third "
                         "held out), each three with the same change, one run each")
    ap.add_argument("--out", type=Path, help="every answer and the scores as JSON")
    args = ap.parse_args(argv)
    labels = args.data / "mixed_labels.json"
    if args.flights is None and not labels.is_file():
        print(f"error: {labels}: not found (give --flights and --reference, or --data)",
              file=sys.stderr)
        return 2
    flights = args.flights or _plain_mixed(args.data)
    references = [] if args.shipped else (
        args.reference or sorted((args.data / "nominal").glob("flight_*.csv.gz")))
    if not flights or not (references or args.shipped):
        print(f"error: {args.data}: no flights found (give --flights and --reference)",
              file=sys.stderr)
        return 2
    delays = args.delays
    if args.logs in ("commands", "imu", "attitude") and delays:    # it lives in the speeds
        print("note: --delays dropped: a rotor-speed logging delay does not reach a log "
              f"without rotor speeds (--logs {args.logs})")
        delays = []
    from quadsim.core.errors import InputError
    from quadsim.logs.flightlog import load_log
    from quadsim.vehicle.params import load_params

    try:
        params = load_params(args.model)
        logs = [load_log(p, warn=False) for p in flights]
        missing = next((p for p in references if not Path(p).is_file()), None)
        if missing is not None:
            raise InputError(f"{missing}: no such file")
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    groups = ([[log] for log in logs] if args.mode == "per-flight" else
              [logs[k:k + 3] for k in range(0, len(logs) - 2, 3)])
    if not groups:
        print("error: --flights: held out needs 3 flights or more (2 training, 1 held out)",
              file=sys.stderr)
        return 2
    kinds = {"mass": args.masses, "rotor": args.rotor_changes,
             "propeller": args.propeller_changes, "delay": delays}
    cases = []          # (the group's changed logs, the change)
    for group, changes in zip(groups, grid(kinds, len(groups), params.rotor_count)):
        for change in changes:
            try:
                cases.append(([injected(log, params, change) for log in group], change))
            except ValueError as exc:       # e.g. saturated motors: no command gives it
                print(f"note: {change.label} not written: {exc}")
    with tempfile.TemporaryDirectory(prefix="qinj_logs_") as folder:
        folder = Path(folder)
        keep = None
        if args.logs != "as-logged":
            from benchmarks.reference_subsets import KEPT, cut_log

            keep = _without_commands if args.logs == "speeds" else KEPT[args.logs]
            (folder / "references").mkdir()
            references = [cut_log(p, keep, folder / "references" / p.name)
                          for p in references]
        written = []
        for k, (changed, change) in enumerate(cases):
            paths = _write([(log, change) for log in changed], folder / f"{k:03d}")
            written.append([p if keep is None else cut_log(p, keep, p) for p in paths])
        try:
            if args.mode == "per-flight":
                result = judge([p for paths in written for p in paths], references,
                               folder / "result.json", args.model)
                answered = {Path(str(f["file"])).name: f for f in result["flights"]}
                entries = [answered[paths[0].name] for paths in written]
            else:
                cache = tempfile.mkdtemp(prefix="qinj_")
                entries = [judge_held_out(paths[:2], paths[2], references,
                                          folder / f"{k:03d}.json", args.model, cache)
                           for k, paths in enumerate(written)]
        except RuntimeError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
    answers = [dict(score(change, entry),
                    flight=" ".join(Path(str(log.path)).name for log in changed))
               for (changed, change), entry in zip(cases, entries)]
    by: dict[str, list] = {}
    for (_, change), answer in zip(cases, answers):
        key = (f"rotor {change.value * 100:+.0f} %" if change.kind == "rotor"
               else change.label)
        by.setdefault(key, []).append(answer)
    judged = "logs" if args.mode == "per-flight" else "held-out runs"
    against = (f"{len(references)} references" if references else
               "the set's shipped reference")
    print(f"{len(flights)} flights, {len(answers)} {judged} judged against {against} "
          f"({args.model})")
    for key, rows in by.items():
        right = sum(r["right"] for r in rows)
        stated = sum(r["stated"] for r in rows)
        wrong = sum(r["confident_wrong"] for r in rows)
        readings = [r["reading"] for r in rows if r["reading"] is not None]
        print(f"  {key:16s} named {right}/{len(rows)}, named or stated beside the name "
              f"{stated}/{len(rows)}, confident wrong {wrong}"
              + (f"; readings {min(readings):+.4g}..{max(readings):+.4g}" if readings else ""))
    if args.out:
        args.out.write_text(json.dumps({"flights": [str(p) for p in flights],
                                        "references": [str(p) for p in references],
                                        "answers": answers}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
