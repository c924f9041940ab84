"""Independent benchmark cases: which flights, from which source, with which hidden effect.

Two sources the diagnosis did not generate (see the independent benchmark section of
docs/gap.md):

* ``rotorpy`` -- :mod:`.rotorpy_source`: RotorPy's own closed loop, integrator, motor,
  aerodynamics and sensor models; effects injected as RotorPy parameters;
* ``pipeline`` -- :mod:`.pipeline`: quadsim's own closed loop (MuJoCo engine), effects
  through quadsim's hooks, but logged through a realistic sensor pipeline
  (finite-difference accelerations, filtered and delayed rotor speeds, mocap latency).

Each case is ``FLIGHTS`` flights of ``DURATION`` s at 250 Hz along one path at a random speed
(varied per flight); every (source, vehicle) pair also has ``REFERENCES`` nominal flights
for the per-flight mode. Cases per vehicle: RotorPy 3 no-effect, 11 in-library (mass x2,
CoM x2, inertia, weak rotor x2, motor lag, body drag, rotor drag, wind), 2 outside
(flapping moment, translational lift: RotorPy physics quadsim's library lacks); pipeline
2 no-effect, 8 in-library, 2 outside (translational lift, blade flapping moment:
:mod:`.outside`). 56 cases in all, plus one ``thrust_factor`` case per source and vehicle,
and a canted rotor and aerodynamic rate damping per vehicle from the pipeline source
(appended, so the seeds of the cases before them stay): 64.

Judging (:func:`run_case`, :func:`run_per_flight`): *held-out* mode
(:func:`quadsim.gap.diagnose`, first ``FLIGHTS - 1`` flights train, the last held out) and
*per-flight* mode (:func:`quadsim.gap.diagnose_per_flight`, each case's first flight against
the reference flights of the same source). A case is *observable* when the library effect
with the true values cuts the held-out gap by at least ``MIN_GAIN``
(:func:`oracle_reduction`).
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import time
import warnings
from pathlib import Path

import numpy as np

from ..core.errors import QuadsimWarning
from ..effects import EFFECTS
from ..vehicle.params import load_params
from .draws import draw, draw_rotorpy, library_equivalent
from .score import read_verdict, score_case

__all__ = ["DURATION", "FLIGHTS", "REFERENCES", "case_flights", "case_list", "heldout_truth",
           "oracle_reduction",
           "reference_flights", "run_case", "run_per_flight"]

VEHICLES = ("physical", "crazyflie21")
FLIGHTS = 3
REFERENCES = 4
DURATION = 8.0
ROTORPY_LIBRARY = ("mass_offset", "mass_offset", "com_offset", "com_offset", "inertia_error",
                   "thrust_mismatch", "thrust_mismatch", "motor_lag", "body_drag", "rotor_drag",
                   "wind")
ROTORPY_OUTSIDE = ("flapping", "translational_lift")
PIPELINE_LIBRARY = ("mass_offset", "com_offset", "thrust_mismatch", "thrust_curve", "battery_sag",
                    "motor_lag", "inertia_error", "rotor_drag")
PIPELINE_OUTSIDE = ("translational_lift", "blade_flapping")
PIPELINE_LATER = ("canted_rotor", "rate_damping")


def case_list(count: int | None = None) -> list[dict]:
    """All cases (dicts with source, vehicle, truth, kind, seed); the first ``count``."""
    cases = []
    for source, none, library, outside in (("rotorpy", 3, ROTORPY_LIBRARY, ROTORPY_OUTSIDE),
                                           ("pipeline", 2, PIPELINE_LIBRARY, PIPELINE_OUTSIDE)):
        for vehicle in VEHICLES:
            cases += [{"source": source, "vehicle": vehicle, "truth": "none", "kind": "none"}
                      for _ in range(none)]
            cases += [{"source": source, "vehicle": vehicle, "truth": n, "kind": "library"}
                      for n in library]
            cases += [{"source": source, "vehicle": vehicle, "truth": n, "kind": "outside"}
                      for n in outside]
    for i, case in enumerate(cases):
        case["seed"] = 5000 + i
    if "thrust_factor" in EFFECTS:  # propeller-thrust effect (appended: seeds above stay)
        for source in ("rotorpy", "pipeline"):
            for vehicle in VEHICLES:
                cases.append({"source": source, "vehicle": vehicle, "truth": "thrust_factor",
                              "kind": "library", "seed": 5000 + len(cases)})
    # later library effects (appended) that RotorPy cannot express (a rotor axis is fixed there;
    # its drag moment is not a damping we can set): the pipeline source only
    for name in PIPELINE_LATER:
        for vehicle in VEHICLES:
            cases.append({"source": "pipeline", "vehicle": vehicle, "truth": name,
                          "kind": "library", "seed": 5000 + len(cases)})
    return cases[:count] if count else cases


#: directory of flown logs (``QUADSIM_BENCH_CACHE``, or ``--cache`` of the benchmark script);
#: unset: every flight is flown anew. Entries are keyed by the case and a hash of the sources'
#: code, so a change of any flight source, draw or effect never reads a stale flight.
CACHE_ENV = "QUADSIM_BENCH_CACHE"


def _code_hash(source: str) -> str:
    """Hash of the code a source's flights depend on (RotorPy: its adapter and its draws;
    pipeline: quadsim's closed loop, effects and sensor pipeline)."""
    import inspect

    from . import draws

    here = Path(__file__).resolve().parent
    top = here.parent
    digest = hashlib.sha256()
    if source == "rotorpy":
        files = [here / "rotorpy_source.py"]
        digest.update(inspect.getsource(draws.draw_rotorpy).encode())
        digest.update(inspect.getsource(draws.library_equivalent).encode())
    else:
        files = ([here / n for n in ("pipeline.py", "draws.py", "outside.py")]
                 + sorted((top / "effects").glob("*.py"))
                 + [top / n for n in ("logs/generate.py", "logs/sensors.py",
                                      "sim/controllers.py", "sim/engines.py",
                                      "sim/mujoco_engine.py", "sim/compiled/__init__.py",
                                      "sim/compiled/layout.py", "sim/compiled/kernel.py",
                                      "sim/paths.py")])
    files += sorted((top.parent / "models").glob("*.toml"))
    for f in files:
        if f.exists():
            digest.update(f.read_bytes())
    return digest.hexdigest()[:16]


def _cached(key: dict, make):
    """``make()`` (a list of FlightLog), stored under the cache directory when one is set."""
    root = os.environ.get(CACHE_ENV)
    if not root:
        return make()
    name = hashlib.sha256(json.dumps({**key, "code": _code_hash(key["source"])}, sort_keys=True,
                                     default=str).encode()).hexdigest()[:24]
    path = Path(root) / f"{name}.pkl"
    if path.exists():
        with open(path, "rb") as handle:
            return pickle.load(handle)
    value = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    with open(tmp, "wb") as handle:
        pickle.dump(value, handle)
    os.replace(tmp, path)
    return value


def _fly(source: str, params, spec, seed: int, speed: float):
    if source == "rotorpy":
        from .rotorpy_source import rotorpy_flight

        return rotorpy_flight(params, spec, seed=seed, duration=DURATION, speed=speed)
    from .pipeline import pipeline_flight

    return pipeline_flight(params, spec, seed=seed, duration=DURATION, speed=speed)


def _spec(case: dict, params, rng):
    if case["truth"] == "none":
        return {} if case["source"] == "rotorpy" else []
    if case["source"] == "rotorpy":
        return draw_rotorpy(case["truth"], params, rng)
    return draw(case["truth"], params, rng)


def case_flights(case: dict):
    """(spec, logs): the hidden effect as the source's parameters and FLIGHTS logs."""
    params = load_params(case["vehicle"])
    rng = np.random.default_rng(case["seed"])
    spec = _spec(case, params, rng)
    speed = rng.uniform(0.7, 1.4)
    logs = _cached({k: case[k] for k in ("source", "vehicle", "truth", "kind", "seed")},
                   lambda: [_fly(case["source"], params, spec, case["seed"] * 10 + s,
                                 speed * (1 + 0.15 * s)) for s in range(FLIGHTS)])
    return spec, logs


def reference_flights(source: str, vehicle: str) -> list:
    """REFERENCES nominal flights of ``source`` (seeds apart from every case's)."""
    params = load_params(vehicle)
    spec = {} if source == "rotorpy" else []
    return _cached({"source": source, "reference": True, "vehicle": vehicle,
                    "count": REFERENCES},
                   lambda: [_fly(source, params, spec, 90_000 + 17 * k + (vehicle == "physical"),
                                 0.8 + 0.15 * k) for k in range(REFERENCES)])


def oracle_reduction(logs, params, effects) -> float:
    """Held-out gap reduction with the *true* library effects and values (observability):
    the last log is held out, the others train (motor map and noise scale, as the
    diagnosis does). For effects upstream of the rotor speed (a battery's speed factor) the
    truth includes the map: the nominal model's map is fitted on the logged speeds (which
    carry the sag), the true model's on the speeds the command gives before the factor
    (speed / factor), so the true factor is not counted twice."""
    import dataclasses

    from ..effects.base import EffectSet
    from ..gap.diagnose import prepare
    from ..gap.fitting import fit_motor_map, noise_floor, noise_scale, residuals

    if not effects:
        return 0.0
    flights = prepare(logs, params)
    train, held = [f.fit for f in flights[:-1]], [f.fit for f in flights[-1:]]
    nominal_params = fit_motor_map(train, params)
    factor_of = EffectSet(tuple(effects)).speed_factor
    unfactored = []
    for f in train:
        factor = factor_of(f.t, f.vbat)
        unfactored.append(f if factor is None or f.rotor_speed is None else dataclasses.replace(
            f, rotor_speed=f.rotor_speed / np.asarray(factor)[:, None]))
    true_params = fit_motor_map(unfactored, params)
    nominal = [residuals(f, nominal_params, [], rotor_channel=True) for f in train]
    sigma = noise_scale(np.concatenate(nominal), float(train[0].t[1] - train[0].t[0]),
                        floor=noise_floor(nominal_params, True))

    def gap(p, eff):
        return np.mean(np.concatenate([residuals(f, p, eff, rotor_channel=True) / sigma
                                       for f in held]) ** 2)

    before = gap(nominal_params, [])
    return float((before - gap(true_params, effects)) / before)


def _truth_effects(case, spec, params) -> list:
    if case["kind"] != "library":
        return []
    return library_equivalent(spec, params) if case["source"] == "rotorpy" else list(spec)


def heldout_truth(case: dict) -> tuple[str, str]:
    """(truth, kind) of a case in held-out mode, where the flights are judged against
    quadsim's nominal model. RotorPy's nominal vehicle has first-order motors
    (:data:`.rotorpy_source.NOMINAL_TAU_M` = 5 ms) and quadsim's nominal model has instant
    rotors, so a RotorPy no-effect flight differs from that model by exactly one physical
    effect, a motor lag: its held-out truth is ``motor_lag`` (in the library). In per-flight
    mode the references are RotorPy's own nominal flights (same motors): truth ``none``."""
    if case["source"] == "rotorpy" and case["truth"] == "none":
        return "motor_lag", "library"
    return case["truth"], case["kind"]


def _describe(spec) -> dict:
    if isinstance(spec, dict):
        return {k: (np.asarray(v).tolist() if not np.isscalar(v) else float(v))
                for k, v in spec.items()}
    return {f"{e.name}.{k}": float(v) for e in spec for k, v in e.values().items() if v}


def run_case(case: dict) -> dict:
    """Fly one case and judge it in held-out mode; the row keeps the first log (for the
    per-flight mode) under ``_log``."""
    from ..gap import diagnose

    warnings.simplefilter("ignore", QuadsimWarning)
    warnings.simplefilter("ignore", RuntimeWarning)
    params = load_params(case["vehicle"])
    spec, logs = case_flights(case)
    start = time.perf_counter()
    result = diagnose(logs[:-1], params, holdout=logs[-1:], kstep=False)
    verdict = read_verdict(result["verdict"])
    truth, kind = heldout_truth(case)
    if truth != case["truth"]:      # RotorPy's nominal 5 ms motors against instant rotors
        from .rotorpy_source import NOMINAL_TAU_M

        truth_effects = [EFFECTS["motor_lag"](time_constant=NOMINAL_TAU_M)]
        verdict.update(truth=truth, kind=kind,
                       oracle_reduction=oracle_reduction(logs, params, truth_effects))
    out = {**case, "spec": _describe(spec), "seconds": time.perf_counter() - start,
           "heldout": {**verdict, "reduction": result["verdict"].get("reduction"),
                       "best_candidate": result["verdict"].get("best_candidate"),
                       "score": score_case(truth, kind, verdict)},
           "oracle_reduction": oracle_reduction(logs, params, _truth_effects(case, spec, params)),
           "_log": logs[0]}
    return out


def run_per_flight(group: tuple[str, str, list[dict]]) -> list[dict]:
    """Per-flight verdicts for the cases of one (source, vehicle) against its references."""
    from ..gap import diagnose_per_flight

    warnings.simplefilter("ignore", QuadsimWarning)
    warnings.simplefilter("ignore", RuntimeWarning)
    source, vehicle, rows = group
    params = load_params(vehicle)
    result = diagnose_per_flight([r["_log"] for r in rows], reference_flights(source, vehicle),
                                 params)
    out = []
    for row, flight in zip(rows, result["flights"]):
        verdict = read_verdict(flight)
        out.append({**verdict, "reduction": flight.get("reduction"),
                    "score": score_case(row["truth"], row["kind"], verdict)})
    return out
