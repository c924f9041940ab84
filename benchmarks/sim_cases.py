"""Frozen single-flight cases of an independent simulator: fly, cache, check, judge once.

Shared by the Crazyflow and PyFlyt sources (:mod:`.crazyflow_cases`, :mod:`.pyflyt_cases`);
each describes itself as a :class:`CaseSource` (its reference flights, its frozen case list,
how to fly a batch, how a case maps to quadsim's library) and this module does the rest the
same way for both:

* :func:`generate` flies the references and every case once (one child process of the
  simulator), writes each flight as ``NAME.csv.gz`` (flight-log schema) with its truth
  sidecar ``NAME.truth.json`` into ``CACHE/<source>-<code hash>/``, and the observability
  of every case (:func:`oracle_reductions`) to ``observability.json``; flights already
  there are kept (same code hash, same bytes);
* :func:`load_flights` reads them back (no verdict);
* :func:`judge` is THE BLIND RUN: per-flight verdicts of every case against the references,
  scored by :mod:`.score`. Run it once, after the verdict rules are frozen.

Observability (:func:`oracle_reductions`): the library effect with the *true difference*
(case minus references, in quadsim's terms) is applied in quadsim's residual model
(:mod:`quadsim.gap.fitting`) on top of the references' shared physics at its true value; a
case is observable when that cuts the flight's normalised residual by at least the source's
threshold. For a rotor-log delay the "true effect" is the log shifted back by the true
delay. The second number is the flight's mean squared normalised residual under the shared
physics relative to the references' own (about 1: nothing the references lack).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

import numpy as np

from quadsim.effects import make_effect

from .observe import TrueModel, per_flight_observability

__all__ = ["MOTOR_TABLE", "PAYLOAD_AS_MASS", "CaseSource", "DrawScale", "code_hash",
           "draw_cases", "draw_effect", "flight_dir", "generate", "judge", "library_difference",
           "load_flights", "motor_library_truth", "oracle_reductions"]


@dataclass(frozen=True)
class CaseSource:
    """One independent simulator's frozen cases.

    name: prefix of the cache folder and of ``truth["source"]``; package: the distribution
    whose version enters the code hash; modules: file names in ``benchmarks/`` the flights
    depend on (hashed); references() -> reference specs; cases() -> case rows (``case``,
    ``truth``, ``kind``, ``seed``, ``speed``, ``effects``); case_spec(case) -> spec;
    fly(specs) -> [(log, truth)]; observe(logs, reference_logs, cases) -> [(reduction, gap
    ratio)]; scored_kind(case) -> the kind a case is scored as; params() -> quadsim's
    parameter set of the simulator's nominal vehicle; observable: the threshold."""

    name: str
    package: str
    modules: tuple[str, ...]
    references: Callable[[], list]
    cases: Callable[[], list[dict]]
    case_spec: Callable[[dict], object]
    fly: Callable[[list], list]
    observe: Callable[[list, list, list], list]
    scored_kind: Callable[[dict], str]
    params: Callable[[], object]
    observable: float
    #: the simulator's version where it is not installed in this interpreter (Genesis runs in
    #: another one: :func:`benchmarks.genesis_source.genesis_version`); None: ``package``'s
    version: Callable[[], str] | None = None


def draw_cases(table, draw: Callable, *, source: str, vehicle: str, seed0: int,
               speeds: tuple[float, float], scored_as: dict) -> list[dict]:
    """A source's frozen cases from its ``table`` of rows (truth, kind, count, speed range or
    None): ``count`` cases per row, each from its own seed ``seed0 + index``: the effects
    drawn by ``draw(truth, rng)`` (numbers as floats, tuples as tuples of floats; none for a
    no-effect case), then the path speed uniform in the row's range (``speeds`` when None).
    Each case: source, vehicle, truth (``scored_as`` maps a case's name to the library name
    it is scored against), case, kind, seed, speed, effects."""
    out = []
    for truth, kind, count, row_speeds in table:
        for _ in range(count):
            seed = seed0 + len(out)
            rng = np.random.default_rng(seed)
            effects = {} if kind == "none" else {
                k: (tuple(float(x) for x in v) if isinstance(v, tuple) else float(v))
                for k, v in draw(truth, rng).items()}
            low, high = row_speeds or speeds
            out.append({"source": source, "vehicle": vehicle,
                        "truth": scored_as.get(truth, truth), "case": truth, "kind": kind,
                        "seed": seed, "speed": float(rng.uniform(low, high)),
                        "effects": effects})
    return out


@dataclass(frozen=True)
class DrawScale:
    """What a source's case magnitudes are drawn against (SI): the vehicle's mass (kg),
    gravity (m/s^2), arm (m), momentum-theory rate damping (N m s/rad,
    :func:`quadsim.gap.fitting.momentum_rate_damping`), the payload's mass, radius off the
    centre and depth below it (each a (low, high) range), and the hover rotor state (a
    thrust curve's linear term is drawn as a share of the hover thrust there; None: the
    source draws no thrust curve), and the wind's speed range (m/s)."""

    mass: float
    gravity: float
    arm: float
    damping: float
    payload_kg: tuple[float, float]
    payload_radius: tuple[float, float]
    payload_below: tuple[float, float]
    hover_state: float | None = None
    wind: tuple[float, float] = (2.0, 5.0)


def draw_effect(truth: str, rng: np.random.Generator, v: DrawScale,
                own: dict[str, Callable] | None = None) -> dict:
    """Source-side effects of ``truth`` at a random realistic magnitude, the ranges of the
    simulator sources' case tables (their modules' docstrings): a mass +5..+20 %; a payload
    in ``v``'s ranges; the CoM 3-10 % of the arm off; Ixx, Iyy +15..+40 %, Izz +0..+20 %; one
    rotor or all -5..-15 %; a linear thrust term of +-5..15 % of the hover thrust at hover;
    both rotor time constants x 1.5-2.5; rate damping 1.5-3 x the momentum value (a third on
    yaw); wind in ``v.wind``; a rotor log 10-30 ms late; a 1-3 Hz torque of 1-3 % of weight
    x arm; a 2-5 Hz vertical force of 1-3 % of the weight. ``own``: truth -> ``draw(rng)``
    for a source's own kinds (a drag scale, a lift, flapping), taking precedence. One angle
    is drawn first, always (the frozen case lists depend on the order of the draws)."""
    weight = v.mass * v.gravity
    angle = rng.uniform(0, 2 * np.pi)
    if own and truth in own:
        return own[truth](rng)
    if truth == "mass_offset":
        return {"mass": rng.uniform(0.05, 0.2) * v.mass}
    if truth == "payload":
        r, a = rng.uniform(*v.payload_radius), rng.uniform(0, 2 * np.pi)
        return {"payload": (rng.uniform(*v.payload_kg), r * np.cos(a), r * np.sin(a),
                            -rng.uniform(*v.payload_below))}
    if truth == "com_offset":
        r = rng.uniform(0.03, 0.1) * v.arm
        return {"com": (r * np.cos(angle), r * np.sin(angle))}
    if truth == "inertia_error":
        return {"inertia": (rng.uniform(0.15, 0.4), rng.uniform(0.15, 0.4), rng.uniform(0, 0.2))}
    if truth == "thrust_mismatch":
        return {"weak_rotor": (int(rng.integers(1, 5)), -rng.uniform(0.05, 0.15))}
    if truth == "thrust_factor":
        return {"thrust_scale": -rng.uniform(0.05, 0.15)}
    if truth == "thrust_curve" and v.hover_state is not None:
        share = rng.uniform(0.05, 0.15) * rng.choice([-1.0, 1.0])
        return {"thrust_linear": share * weight / 4 / v.hover_state}
    if truth == "motor_lag":
        return {"motor_slow": rng.uniform(1.5, 2.5)}
    if truth == "rate_damping":
        k = rng.uniform(1.5, 3.0) * v.damping
        return {"rate_damping": (k, k, k / 3.0)}
    if truth == "wind":
        speed = rng.uniform(*v.wind)
        return {"wind": (speed * np.cos(angle), speed * np.sin(angle))}
    if truth == "rotor_delay":
        return {"rotor_delay": rng.uniform(0.010, 0.030)}
    if truth == "periodic_torque":
        amp = rng.uniform(0.01, 0.03) * weight * v.arm
        return {"torque": (amp * np.cos(angle), amp * np.sin(angle), 0.0),
                "torque_hz": rng.uniform(1.0, 3.0)}
    if truth == "periodic_force":
        return {"force": rng.uniform(0.01, 0.03) * weight, "force_hz": rng.uniform(2.0, 5.0)}
    raise ValueError(f"no case {truth!r}")


def library_difference(effects: dict, *, thrust_alpha: float = 0.0,
                       linear_per_speed: float = 0.0, rate_damping: bool = False) -> list:
    """A case's true difference from its references as library effects, from the case-side
    ``effects`` every simulator source names alike: flap (``blade_flapping``), lift
    (``translational_lift`` k_h), mass, payload (an offset ``mass_offset``), com, inertia,
    weak_rotor (``thrust_mismatch``), thrust_scale (``thrust_factor`` with the source's
    speed-per-command exponent ``thrust_alpha``), thrust_linear (``thrust_curve``: N per unit
    normalised rotor state times ``linear_per_speed``, that state per rad/s), rate_damping
    (``rate_damping`` x, y, z in N m s/rad where ``rate_damping`` is True: a source whose
    references share none), wind. [] where the change only scales the references' shared
    physics (a slower motor, a drag or damping scale): the source's shared effects carry it."""
    e = effects
    if "flap" in e:
        return [make_effect("blade_flapping", coefficient=e["flap"])]
    if "lift" in e:
        return [make_effect("translational_lift", k_h=e["lift"])]
    if "mass" in e:
        return [make_effect("mass_offset", mass=e["mass"])]
    if "payload" in e:
        m, x, y, z = e["payload"]
        return [make_effect("mass_offset", mass=m, x=x, y=y, z=z)]
    if "com" in e:
        return [make_effect("com_offset", x=e["com"][0], y=e["com"][1])]
    if "inertia" in e:
        xx, yy, zz = e["inertia"]
        return [make_effect("inertia_error", xx=xx, yy=yy, zz=zz)]
    if "weak_rotor" in e:
        i, d = e["weak_rotor"]
        return [make_effect("thrust_mismatch", **{f"rotor_{int(i)}": d})]
    if "thrust_scale" in e:
        return [make_effect("thrust_factor", change=e["thrust_scale"], alpha=thrust_alpha)]
    if "thrust_linear" in e:
        return [make_effect("thrust_curve", linear=e["thrust_linear"] * linear_per_speed)]
    if rate_damping and "rate_damping" in e:
        k = e["rate_damping"]
        return [make_effect("rate_damping", x=k[0], y=k[1], z=k[2])]
    if "wind" in e:
        return [make_effect("wind", vx=e["wind"][0], vy=e["wind"][1])]
    return []


#: the case table of the simulator sources with a DC motor and no thrust curve of their own
#: (:mod:`.multirotor_cases`, :mod:`.qcsim_cases`, :mod:`.genesis_cases`; each module's
#: docstring has the ranges): (truth, kind, count, speed range or None), 28 cases
MOTOR_TABLE = (("none", "none", 2, (0.75, 1.35)), ("none", "none", 2, (0.45, 0.55)),
               ("none", "none", 2, (1.5, 1.65)),
               ("mass_offset", "library", 2, None), ("payload", "library", 1, None),
               ("com_offset", "library", 2, None), ("inertia_error", "library", 2, None),
               ("thrust_mismatch", "library", 2, None), ("thrust_factor", "library", 1, None),
               ("motor_lag", "library", 2, None), ("rate_damping", "library", 2, None),
               ("wind", "library", 2, None), ("rotor_delay", "library", 2, None),
               ("periodic_torque", "outside", 2, None), ("periodic_force", "outside", 2, None))
#: library name a case's truth is scored against (a payload is an offset mass)
PAYLOAD_AS_MASS = {"payload": "mass_offset"}


def motor_library_truth(case: dict, shared: list, motor_alpha: Callable[[float], float],
                        kind: str) -> list:
    """Library effects with the true difference of a :data:`MOTOR_TABLE` ``case`` on top of
    the source's ``shared`` effects (the case's true model; a propeller change with the DC
    motor's speed-per-command exponent ``motor_alpha(change)``, rate damping as the library's:
    those sources' references share none); [] for cases scored outside the library (``kind``)
    and for a late rotor log."""
    e = case["effects"]
    if kind != "library" or "rotor_delay" in e:
        return []
    alpha = motor_alpha(e["thrust_scale"]) if "thrust_scale" in e else 0.0
    # [] for motor_slow: the shared motor lag scaled
    return shared + library_difference(e, thrust_alpha=alpha, rate_damping=True)


def code_hash(source: CaseSource) -> str:
    """Hash of everything the flights depend on: the source's modules, the simulator's
    version, the reference specs and the case list (a change never reads a stale flight)."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256((source.version() if source.version else
                             version(source.package)).encode())
    for name in source.modules:
        digest.update((here / name).read_bytes())
    digest.update(repr([(s.seed, s.speed, s.duration) for s in source.references()]).encode())
    digest.update(repr(source.cases()).encode())
    return digest.hexdigest()[:12]


def flight_dir(source: CaseSource, cache) -> Path:
    return Path(cache) / f"{source.name}-{code_hash(source)}"


def _name(role: str, k: int, truth: str) -> str:
    return f"{role}_{k:02d}_{truth}" if role == "case" else f"{role}_{k:02d}"


def generate(source: CaseSource, cache, progress=print) -> Path:
    """Fly, write and check every flight of ``source`` (module docstring); the folder."""
    from quadsim.core.files import atomic_write_text
    from quadsim.logs.flightlog import load_log, write_log

    from .simlog import truth_json

    out = flight_dir(source, cache)
    out.mkdir(parents=True, exist_ok=True)
    cases = source.cases()
    jobs = ([(_name("ref", k, ""), s, None) for k, s in enumerate(source.references())]
            + [(_name("case", k, c["case"]), source.case_spec(c), c)
               for k, c in enumerate(cases)])
    todo = [j for j in jobs if not (out / f"{j[0]}.csv.gz").exists()]
    if todo:
        progress(f"{source.name}: flying {len(todo)} flights in one child process")
        for (name, _, case), (log, truth) in zip(todo, source.fly([j[1] for j in todo])):
            if case is not None:
                truth = {**truth, "truth": case["truth"], "kind": case["kind"],
                         "case": case["case"]}
            atomic_write_text(out / f"{name}.truth.json", truth_json(truth))
            write_log(out / f"{name}.csv.gz", log)
    if not todo and (out / "observability.json").exists():
        return out
    refs = [load_log(out / f"{name}.csv.gz", warn=False) for name, _, c in jobs if c is None]
    named = [(name, case) for name, _, case in jobs if case is not None]
    logs = [load_log(out / f"{name}.csv.gz", warn=False) for name, _ in named]
    observed = {n: {"reduction": r, "gap": g} for n, (r, g) in
                zip([n for n, _ in named], source.observe(logs, refs, [c for _, c in named]))}
    atomic_write_text(out / "observability.json",
                      json.dumps(observed, indent=1, sort_keys=True) + "\n")
    return out


def load_flights(source: CaseSource, cache) -> tuple[list, list[dict]]:
    """(reference logs, case rows with ``_log`` and ``oracle_reduction``) from
    :func:`generate`'s folder; raises FileNotFoundError when it is incomplete."""
    from quadsim.logs.flightlog import load_log

    out = flight_dir(source, cache)
    observed = json.loads((out / "observability.json").read_text())
    refs = [load_log(out / f"{_name('ref', k, '')}.csv.gz", warn=False)
            for k in range(len(source.references()))]
    rows = []
    for k, case in enumerate(source.cases()):
        name = _name("case", k, case["case"])
        kind = source.scored_kind(case)
        rows.append({**case, "kind": kind, "flown_as": case["kind"], "name": name,
                     "_log": load_log(out / f"{name}.csv.gz", warn=False),
                     "oracle_reduction": observed[name]["reduction"],
                     "gap_vs_references": observed[name]["gap"],
                     "observable": (kind != "library"
                                    or observed[name]["reduction"] >= source.observable)})
    return refs, rows


def judge(source: CaseSource, cache) -> list[dict]:
    """THE BLIND RUN: per-flight verdicts of every case against the references, scored
    (:mod:`.score`), each row with the references' self-check (``self_check``: how many
    references, clean, the false alarms as (flight, verdict), their channels; None where the
    diagnosis made none). Run it once, after the verdict rules are frozen."""
    from quadsim.core.errors import QuadsimWarning
    from quadsim.gap import diagnose_per_flight

    from .score import read_verdict, score_case

    refs, rows = load_flights(source, cache)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        result = diagnose_per_flight([r["_log"] for r in rows], refs, source.params())
    seconds = time.perf_counter() - start
    check = (result["reference_model"] or {}).get("self_check")
    self_check = None if check is None else {
        "flights": len(check["flights"]), "clean": check["clean"],
        "false_alarms": [[a["flight"], a["verdict"]] for a in check["false_alarms"]],
        "channels": check["channels"]}
    out = []
    for row, flight in zip(rows, result["flights"]):
        verdict = read_verdict(flight)
        row = {k: v for k, v in row.items() if k != "_log"}
        out.append({**row, "effects": {k: np.asarray(v).tolist() for k, v in
                                       row["effects"].items()},
                    "per_flight": {**verdict, "reduction": flight.get("reduction"),
                                   "probability_within_library":
                                       flight.get("probability_within_library"),
                                   "score": score_case(row["truth"], row["kind"], verdict)},
                    "seconds_all": seconds, "self_check": self_check})
    return out


def oracle_reductions(logs: list, references: list, cases: list[dict], params,
                      shared: list, truth: Callable[[dict], list],
                      scored_kind: Callable[[dict], str]) -> list[tuple[float, float]]:
    """Per case (reduction, gap): :func:`benchmarks.observe.per_flight_observability` with
    the references' ``shared`` physics and each case's true model (``truth(case)``, the full
    effect list; a late rotor log: the shared physics on the log shifted back by the true
    delay): the cut of its flight's normalised residual (forces, torques, rotor channel) when
    the true difference is applied in quadsim's residual model, 0 for cases scored outside the
    library; and the flight's mean squared normalised residual under ``shared`` relative to
    the references' own."""
    truths = []
    for log, case in zip(logs, cases):
        if scored_kind(case) != "library":
            truths.append(None)
        elif "rotor_delay" in case["effects"]:
            delay = float(case["effects"]["rotor_delay"])
            truths.append(TrueModel(tuple(shared), dataclasses.replace(log, rotor_speed=np.stack(
                [np.interp(log.t + delay, log.t, c) for c in log.rotor_speed.T], axis=-1))))
        else:
            truths.append(TrueModel(tuple(truth(case))))
    return [tuple(o) for o in per_flight_observability(logs, references, params, shared,
                                                        truths)]
