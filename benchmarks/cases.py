"""Independent benchmark cases: which flights, from which source, with which hidden effect.

Two sources the diagnosis did not generate (see the independent benchmark section of
docs/gap.md):

* ``rotorpy`` -- :mod:`.rotorpy_source`: RotorPy's own closed loop, integrator, motor,
  aerodynamics and sensor models; effects injected as RotorPy parameters;
* ``pipeline`` -- :mod:`.pipeline`: quadsim's own closed loop (MuJoCo engine), effects
  through quadsim's hooks, but logged through a realistic sensor pipeline
  (finite-difference accelerations, filtered and delayed rotor speeds, mocap latency).

Each case is ``FLIGHTS`` flights of ``DURATION`` s at 250 Hz along one path at a random speed
(0.7-1.4 x the path's base speed for the first flight, +15 % per further flight); every
(source, vehicle) pair also has ``REFERENCES`` nominal flights for the per-flight mode, at
path speeds evenly over ``REFERENCE_SPEEDS`` (0.65-1.5: they span the cases' first flights).
Cases per vehicle: RotorPy 3 no-effect, 11 in-library (mass x2,
CoM x2, inertia, weak rotor x2, motor lag, body drag, rotor drag, wind), 2 outside
(flapping moment, translational lift: RotorPy physics quadsim's library lacks); pipeline
2 no-effect, 8 in-library, 2 outside (translational lift, blade flapping moment:
:mod:`.outside`). 56 cases in all, plus one ``thrust_factor`` case per source and vehicle,
and a canted rotor and aerodynamic rate damping per vehicle from the pipeline source
(appended, so the seeds of the cases before them stay): 64. The flapping and lift cases
flown as outside are scored as in-library since the library gained them
(:data:`JOINED_LIBRARY`), which left both sources' out-of-library sets empty; issue 47's
out-of-library cases are appended after them (:data:`PIPELINE_UNMODELLED`, effects of
:mod:`.unmodelled`: rotor-rotor wake interference and the frame's drag moment, pipeline
source only; RotorPy none, :data:`ROTORPY_UNMODELLED`): 68; then a gyro mounted askew per
vehicle (:data:`PIPELINE_SENSOR`, :mod:`.imu_error`, sensor side, pipeline source): 70.

Judging (:func:`run_case`, :func:`run_per_flight`): *held-out* mode
(:func:`quadsim.gap.diagnose`, first ``FLIGHTS - 1`` flights train, the last held out) and
*per-flight* mode (:func:`quadsim.gap.diagnose_per_flight`, each case's first flight against
the reference flights of the same source and vehicle, the design of the Crazyflow source,
:mod:`.crazyflow_cases`). Observability: in held-out mode a case counts when the library
effect with the true values cuts the held-out gap by at least :data:`benchmarks.observe.MIN_GAIN`
(:func:`oracle_reduction`); in per-flight mode when the true difference from the references
(:func:`per_flight_truth`: the source's shared physics, :func:`shared_physics`, with the
hidden effect) cuts *that flight's* residual by at least
:data:`benchmarks.observe.OBSERVABLE` (:func:`per_flight_observed`).

Flights are cached per case (all ``FLIGHTS``, :func:`case_flights`), per first flight alone
(:func:`first_flight`, when only the per-flight mode asked for it; the full set reuses it)
and per reference flight (:func:`reference_flight`).
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

from quadsim.core.errors import QuadsimWarning
from quadsim.effects import EFFECTS
from quadsim.vehicle.params import load_params

from .draws import draw, draw_rotorpy, library_equivalent
from .observe import OBSERVABLE, Observed, TrueModel, per_flight_observability, true_model
from .score import joined_kind, read_verdict, score_case

__all__ = [
    "DURATION",
    "FLIGHTS",
    "JOINED_LIBRARY",
    "REFERENCES",
    "REFERENCE_SPEEDS",
    "case_flights",
    "case_key",
    "case_list",
    "first_flight",
    "heldout_truth",
    "is_cached",
    "oracle_reduction",
    "per_flight_observed",
    "per_flight_truth",
    "reference_flight",
    "reference_flights",
    "reference_key",
    "reference_speeds",
    "run_case",
    "run_per_flight",
    "scored_kind",
    "shared_physics",
    "unmodelled_cases",
]

VEHICLES = ("physical", "crazyflie21")
FLIGHTS = 3
REFERENCES = 8
#: path-speed range of the reference flights (x the path's base speed)
REFERENCE_SPEEDS = (0.65, 1.5)
DURATION = 8.0
ROTORPY_LIBRARY = ("mass_offset", "mass_offset", "com_offset", "com_offset", "inertia_error",
                   "thrust_mismatch", "thrust_mismatch", "motor_lag", "body_drag", "rotor_drag",
                   "wind")
ROTORPY_OUTSIDE = ("flapping", "translational_lift")
PIPELINE_LIBRARY = ("mass_offset", "com_offset", "thrust_mismatch", "thrust_curve", "battery_sag",
                    "motor_lag", "inertia_error", "rotor_drag")
PIPELINE_OUTSIDE = ("translational_lift", "blade_flapping")
PIPELINE_LATER = ("canted_rotor", "rate_damping")
#: cases flown as outside the library whose effect the diagnosis has gained since: RotorPy's
#: k_h lift (:mod:`quadsim.effects.translational_lift`, per rotor) and the flapping moment of
#: RotorPy (``flapping``) and of the pipeline (:mod:`quadsim.effects.blade_flapping`, a
#: per-flight reading since issue 45): their flights and cache keys stay, they are scored
#: as in-library (:func:`scored_kind`).
JOINED_LIBRARY = frozenset({"translational_lift", "flapping", "blade_flapping"})
#: out-of-library cases added by issue 47 (appended after every case above, so no seed, flight
#: or cache key of those moves): effects of :mod:`.unmodelled` flown through quadsim's hooks
PIPELINE_UNMODELLED = ("rotor_wake", "frame_moment")
#: RotorPy has none: every aerodynamic term its ``quad_params`` offers (parasitic drag
#: ``c_D*``, rotor drag ``k_d``, induced inflow ``k_z``, translational lift ``k_h``, flapping
#: ``k_flap``, first-order motors ``tau_m``) is a library reading now; what else its
#: configuration offers is sensor-side (its IMU's mounting rotation ``R_BS`` and lever arm
#: ``p_BS``, biases and random walk) or white rotor-speed noise (``motor_noise_std``), and
#: flying those needs the adapter (:mod:`.rotorpy_source`) changed, whose bytes key every
#: cached RotorPy flight (:func:`_code_hash`)
ROTORPY_UNMODELLED: tuple[str, ...] = ()
#: issue 47's sensor-side out-of-library case (appended after the cases above): the
#: pipeline's logged gyro turned from the body axes (:mod:`.imu_error`)
PIPELINE_SENSOR = ("gyro_misalignment",)


def scored_kind(case: dict) -> str:
    """The kind a case is scored as today (see :data:`JOINED_LIBRARY`)."""
    return joined_kind(case["truth"], case["kind"], JOINED_LIBRARY)


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
    # issue 47's out-of-library cases (appended: the seeds above stay)
    for source, names in (("rotorpy", ROTORPY_UNMODELLED), ("pipeline", PIPELINE_UNMODELLED)):
        for name in names:
            for vehicle in VEHICLES:
                cases.append({"source": source, "vehicle": vehicle, "truth": name,
                              "kind": "outside", "seed": 5000 + len(cases)})
    for name in PIPELINE_SENSOR:
        for vehicle in VEHICLES:
            cases.append({"source": "pipeline", "vehicle": vehicle, "truth": name,
                          "kind": "outside", "seed": 5000 + len(cases)})
    return cases[:count] if count else cases


def unmodelled_cases() -> list[dict]:
    """Issue 47's out-of-library cases (:mod:`.unmodelled`, :mod:`.imu_error`), as
    :func:`case_list` has them (seeds 5064 on)."""
    from .unmodelled import UNMODELLED

    return [c for c in case_list() if c["truth"] in UNMODELLED or c["truth"] in PIPELINE_SENSOR]


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
    top = here.parent / "quadsim"
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


def _unmodelled_hash(key: dict) -> dict:
    """``{"unmodelled": hash}`` of :mod:`.unmodelled`'s file for a case that flies one of its
    effects (``{"imu_error": hash}`` of :mod:`.imu_error`'s for a gyro case), else ``{}`` (so
    the keys of every other case and reference stay as they were)."""
    from .unmodelled import UNMODELLED

    here = Path(__file__).resolve().parent
    if key.get("truth") in PIPELINE_SENSOR:
        data = (here / "imu_error.py").read_bytes()
        return {"imu_error": hashlib.sha256(data).hexdigest()[:16]}
    if key.get("truth") not in UNMODELLED:
        return {}
    data = (here / "unmodelled.py").read_bytes()
    return {"unmodelled": hashlib.sha256(data).hexdigest()[:16]}


def _entry(key: dict) -> Path | None:
    """The cache file of ``key`` (None: no cache directory is set)."""
    root = os.environ.get(CACHE_ENV)
    if not root:
        return None
    name = hashlib.sha256(json.dumps({**key, **_unmodelled_hash(key),
                                      "code": _code_hash(key["source"])}, sort_keys=True,
                                     default=str).encode()).hexdigest()[:24]
    return Path(root) / f"{name}.pkl"


def is_cached(key: dict) -> bool:
    """Whether the flights of ``key`` are in the cache directory."""
    path = _entry(key)
    return path is not None and path.exists()


def _cached(key: dict, make):
    """``make()`` (a FlightLog or a list of them), stored under the cache directory when one
    is set."""
    path = _entry(key)
    if path is None:
        return make()
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
    from .imu_error import GyroMisalignment
    from .pipeline import pipeline_flight

    sensors = [s for s in spec if isinstance(s, GyroMisalignment)]
    log = pipeline_flight(params, [e for e in spec if not isinstance(e, GyroMisalignment)],
                          seed=seed, duration=DURATION, speed=speed)
    for sensor in sensors:       # sensor side, after the pipeline (benchmarks.imu_error)
        log = sensor.apply(log)
    return log


def _spec(case: dict, params, rng):
    from .unmodelled import UNMODELLED, draw_unmodelled

    if case["truth"] == "none":
        return {} if case["source"] == "rotorpy" else []
    if case["truth"] in UNMODELLED:
        return draw_unmodelled(case["truth"], params, rng)
    if case["truth"] in PIPELINE_SENSOR:
        from .imu_error import draw_gyro_misalignment

        return draw_gyro_misalignment(params, rng)
    if case["source"] == "rotorpy":
        return draw_rotorpy(case["truth"], params, rng)
    return draw(case["truth"], params, rng)


def case_key(case: dict, first_only: bool = False) -> dict:
    """Cache key of a case's FLIGHTS flights, or of its first flight alone (``first_only``,
    all the per-flight mode needs)."""
    key = {k: case[k] for k in ("source", "vehicle", "truth", "kind", "seed")}
    return {**key, "flight": 0} if first_only else key


def _case_setup(case: dict):
    """(params, spec, speed of the first flight): the case's draw from its seed."""
    params = load_params(case["vehicle"])
    rng = np.random.default_rng(case["seed"])
    spec = _spec(case, params, rng)
    return params, spec, rng.uniform(0.7, 1.4)


def _case_flight(case: dict, params, spec, speed: float, s: int):
    """Flight ``s`` of a case: seed ``10 seed + s``, path speed ``speed (1 + 0.15 s)``."""
    return _fly(case["source"], params, spec, case["seed"] * 10 + s, speed * (1 + 0.15 * s))


def first_flight(case: dict):
    """(spec, log): the hidden effect and the case's first flight (the per-flight mode's),
    read from the case's FLIGHTS flights when they are cached, else flown (and cached) alone."""
    params, spec, speed = _case_setup(case)
    if is_cached(case_key(case)):
        return spec, _cached(case_key(case), None)[0]
    return spec, _cached(case_key(case, first_only=True),
                         lambda: _case_flight(case, params, spec, speed, 0))


def case_flights(case: dict):
    """(spec, logs): the hidden effect as the source's parameters and FLIGHTS logs (the first
    one read from the cache when :func:`first_flight` flew it already)."""
    params, spec, speed = _case_setup(case)

    def make():
        first = (_cached(case_key(case, first_only=True), None)
                 if is_cached(case_key(case, first_only=True))
                 else _case_flight(case, params, spec, speed, 0))
        return [first] + [_case_flight(case, params, spec, speed, s) for s in range(1, FLIGHTS)]

    return spec, _cached(case_key(case), make)


def reference_speeds() -> np.ndarray:
    """Path speeds of the REFERENCES nominal flights: evenly over :data:`REFERENCE_SPEEDS`,
    which spans the speeds of the cases' first flights (0.7-1.4)."""
    return np.linspace(*REFERENCE_SPEEDS, REFERENCES)


def reference_key(source: str, vehicle: str, k: int) -> dict:
    """Cache key of reference flight ``k`` (one entry per flight)."""
    return {"source": source, "reference": k, "vehicle": vehicle,
            "seed": 90_000 + 17 * k + (vehicle == "physical"),
            "speed": round(float(reference_speeds()[k]), 9)}


def reference_flight(source: str, vehicle: str, k: int):
    """Nominal flight ``k`` of ``source`` (seeds apart from every case's)."""
    key = reference_key(source, vehicle, k)
    params = load_params(vehicle)
    spec = {} if source == "rotorpy" else []
    return _cached(key, lambda: _fly(source, params, spec, key["seed"], key["speed"]))


def reference_flights(source: str, vehicle: str) -> list:
    """The REFERENCES nominal flights of ``source`` (:func:`reference_flight`)."""
    return [reference_flight(source, vehicle, k) for k in range(REFERENCES)]


def oracle_reduction(logs, params, effects) -> float:
    """Held-out gap reduction with the *true* library effects and values (observability):
    the last log is held out, the others train (motor map, as the diagnosis fits it,
    :func:`quadsim.gap.diagnose.training_map`, and noise scale). For effects upstream of
    the rotor speed (a battery's speed factor) the truth includes the map: the nominal
    model's map is fitted on the logged speeds (which carry the sag), the true model's on
    the speeds the command gives before the factor (speed / factor), so the true factor is
    not counted twice."""
    import dataclasses

    from quadsim.effects.base import EffectSet
    from quadsim.gap.diagnose import prepare, training_map
    from quadsim.gap.fitting import noise_floor, noise_scale, residuals

    if not effects:
        return 0.0
    flights = prepare(logs, params)
    train, held = [f.fit for f in flights[:-1]], [f.fit for f in flights[-1:]]
    nominal_params = training_map(train, params)
    factor_of = EffectSet(tuple(effects)).command_factor
    unfactored = []
    for f in train:
        factor = None if f.rotor_speed is None else factor_of(f.t, f.vbat,
                                                               f.rotor_speed.shape[1])
        unfactored.append(f if factor is None else dataclasses.replace(
            f, rotor_speed=f.rotor_speed / factor))
    true_params = training_map(unfactored, params)
    nominal = [residuals(f, nominal_params, [], rotor_channel=True) for f in train]
    sigma = noise_scale(np.concatenate(nominal), float(train[0].t[1] - train[0].t[0]),
                        floor=noise_floor(nominal_params, True))

    def gap(p, eff):
        return np.mean(np.concatenate([residuals(f, p, eff, rotor_channel=True) / sigma
                                       for f in held]) ** 2)

    before = gap(nominal_params, [])
    return float((before - gap(true_params, effects)) / before)


def _truth_effects(case, spec, params) -> list:
    if scored_kind(case) != "library":
        return []
    if case["source"] != "rotorpy":
        return list(spec)
    return library_equivalent(spec, params) + rotorpy_flapping(spec)


def rotorpy_flapping(spec: dict) -> list:
    """RotorPy's flapping moment as the library's (:mod:`quadsim.effects.blade_flapping`): its
    ``-k_flap Omega_i (v x e_z)``, v the vehicle's airspeed, is the library's
    ``-c Omega_i (e_z x v_perp)`` at ``c = -k_flap`` (both axes); [] without one. Here, not in
    :func:`.draws.library_equivalent`, whose source keys the flown RotorPy flights' cache."""
    if "k_flap" not in spec:
        return []
    return [EFFECTS["blade_flapping"](coefficient=-float(spec["k_flap"]))]


def heldout_truth(case: dict) -> tuple[str, str]:
    """(truth, kind) of a case in held-out mode, where the flights are judged against
    quadsim's nominal model. RotorPy's nominal vehicle has first-order motors
    (:data:`.rotorpy_source.NOMINAL_TAU_M` = 5 ms) and quadsim's nominal model has instant
    rotors, so a RotorPy no-effect flight differs from that model by exactly one physical
    effect, a motor lag: its held-out truth is ``motor_lag`` (in the library). In per-flight
    mode the references are RotorPy's own nominal flights (same motors): truth ``none``."""
    if case["source"] == "rotorpy" and case["truth"] == "none":
        return "motor_lag", "library"
    return case["truth"], scored_kind(case)


def _describe(spec) -> dict:
    if isinstance(spec, dict):
        return {k: (np.asarray(v).tolist() if not np.isscalar(v) else float(v))
                for k, v in spec.items()}
    return {f"{e.name}.{k}": float(v) for e in spec for k, v in e.values().items() if v}


def run_case(case: dict) -> dict:
    """Fly one case and judge it in held-out mode; the row keeps the first log (for the
    per-flight mode) under ``_log``."""
    from quadsim.gap import diagnose

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


def shared_physics(source: str) -> list:
    """The physics every flight of ``source`` shares (its references' included) that quadsim's
    nominal model lacks, as library effects at their true values: RotorPy's first-order
    motors (:data:`.rotorpy_source.NOMINAL_TAU_M`); nothing for the sensor pipeline (quadsim's
    own closed loop; its sensor filters and delays are in every reference too)."""
    if source == "rotorpy":
        from .rotorpy_source import NOMINAL_TAU_M

        return [EFFECTS["motor_lag"](time_constant=NOMINAL_TAU_M)]
    return []


def per_flight_truth(case: dict) -> TrueModel | None:
    """The true model of a case's first flight against its source's references (shared
    physics with the true difference, :func:`benchmarks.observe.true_model`); None for a
    case with no library form (no effect, outside the library)."""
    if scored_kind(case) != "library":
        return None
    params, spec, _ = _case_setup(case)
    return TrueModel(true_model(shared_physics(case["source"]),
                                _truth_effects(case, spec, params)))


def per_flight_observed(source: str, vehicle: str, rows: list[dict],
                        references: list | None = None) -> list[Observed]:
    """:class:`benchmarks.observe.Observed` of each row's first flight (``_log``) against
    the references of (source, vehicle): the per-flight mode's observability."""
    references = reference_flights(source, vehicle) if references is None else references
    return per_flight_observability([r["_log"] for r in rows], references,
                                    load_params(vehicle), shared_physics(source),
                                    [per_flight_truth(r) for r in rows])


def run_per_flight(group: tuple[str, str, list[dict]]) -> list[dict]:
    """Per-flight verdicts for the cases of one (source, vehicle) against its references,
    each with its per-flight observability (``oracle_reduction``: the true difference's cut
    of that flight's residual; ``gap_vs_references``; ``observable``)."""
    from quadsim.gap import diagnose_per_flight

    warnings.simplefilter("ignore", QuadsimWarning)
    warnings.simplefilter("ignore", RuntimeWarning)
    source, vehicle, rows = group
    params = load_params(vehicle)
    references = reference_flights(source, vehicle)
    observed = per_flight_observed(source, vehicle, rows, references)
    result = diagnose_per_flight([r["_log"] for r in rows], references, params)
    out = []
    for row, flight, seen in zip(rows, result["flights"], observed):
        verdict = read_verdict(flight)
        kind = scored_kind(row)
        out.append({**verdict, "reduction": flight.get("reduction"),
                    "score": score_case(row["truth"], kind, verdict),
                    "oracle_reduction": seen.reduction, "gap_vs_references": seen.gap,
                    "observable": kind != "library" or seen.reduction >= OBSERVABLE,
                    **_why(flight)})
    return out


def _why(flight: dict) -> dict:
    """What a per-flight verdict rests on: its most probable reading (also under an
    ``unexplained`` verdict), that reading's probability, the channels failing the lack-of-fit
    test (ratio of the flight's RMS to the references') and the answer text."""
    posterior = flight.get("posterior") or [{}]
    return {"lead_reading": posterior[0].get("name"),
            "lead_probability": posterior[0].get("probability"),
            "lack_of_fit": {k: float(v) for k, v in (flight.get("lack_of_fit") or {}).items()},
            "answer": flight.get("answer")}
