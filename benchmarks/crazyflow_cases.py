"""Crazyflow benchmark cases: each a single flight judged per flight against 8 nominal Crazyflow
flights.

Source: :mod:`.crazyflow_source` (Crazyflow's own dynamics, RK4 integrator, Mellinger
controller and Crazyflie 2.1 Brushless model; quadsim only converts the log). The cases are
*frozen*: drawn once from fixed seeds (:func:`case_list`), cached by
``benchmarks/gap_benchmark.py --independent --source crazyflow --generate-only --cache DIR``,
and judged once (``--independent --source crazyflow --cache DIR``) after the verdict rules
are frozen. Nothing here was tuned on how the diagnosis does on them.

Cases (:func:`case_list`, 28; every flight 8 s at 500 Hz after a 1 s lead-in, path speed
0.8-1.25 x unless stated), magnitudes drawn uniformly (SI) in Crazyflow's own terms:

===============  ========================================  ================================
truth            Crazyflow change (range)                  source of the range
===============  ========================================  ================================
none x 6         nothing; 2 at speed 0.8-1.2, 2 slower      the references' own spread
                 (0.55-0.65), 2 faster (1.35-1.5)
mass_offset x2   mass +5..+20 % (2.2-8.7 g at the CoM)      a heavier battery/deck: the
                                                           CF 2.1 decks weigh 1.5-8 g
mass_offset      payload 4-8 g at 5-15 mm from the centre,  a deck or marker mount off
(payload)        5-10 mm below: mass, CoM, inertia          centre
com_offset x2    CoM 3-10 % of the arm (1.5-5 mm)           battery placement (the same
                                                           range as the RotorPy cases)
inertia_error x2 Jxx, Jyy +15..+40 %, Jzz +0..+20 %         CAD vs pendulum inertias of
                                                           small quads differ 10-40 %
thrust_mismatch  one rotor's thrust and torque curve        a chipped or bent propeller
 x2              -5..-15 %                                 (5-15 % less thrust)
thrust_factor    every curve -5..-15 %                      worn propellers, heat
motor_lag x2     rotor-dynamics coefficients / 1.5-2.5      a slower ESC/motor: time
                 (57 ms -> 85-140 ms at hover)             constants 20-150 ms in the
                                                           literature (motor_lag docs)
rotor_drag x2    body drag x 1.5-2.5 (x, y)                 prop guards / cage; the issue's
                                                           "rotor drag doubled"
wind x2          steady wind 1-2.5 m/s, random direction    indoor fans, outdoor calm
                 (through Crazyflow's own drag matrix)
rotor_delay x2   rotor-speed log 10-30 ms late              ESC telemetry 10-30 ms
                                                           (docs/delays.md)
outside x 4      translational lift +2..+5 % thrust at      RotorPy's k_h model; Mahony
                 1.5 m/s; blade-flapping moment 2-4 %       et al. 2012; a cable or loose
                 of weight x arm at 1 m/s; a 1-3 Hz         part tugging
                 roll/pitch torque 1-3 % of weight x arm
===============  ========================================  ================================

Observability (:func:`oracle_reductions`): the library effect with the *true difference*
(case minus references, in quadsim's terms, :func:`library_truth`) is applied in quadsim's
residual model (:mod:`quadsim.gap.fitting`) on top of the references' shared physics at its
true value (:func:`shared_effects`: Crazyflow's 57/62 ms rotor dynamics and its body drag,
both linearised at hover); a case is observable when that cuts the flight's normalised
residual by at least :data:`OBSERVABLE` (5 %). For a rotor-log delay the "true effect" is
the log shifted back by the true delay. Cases below it are scored apart and marked, never
dropped.

Scoring (:mod:`.score`): in-library -> a reading of the verdict names the truth (a delay:
any reading whose name contains ``delay``); no effect -> ``no_significant_gap``;
out-of-library -> no confident name.
"""

from __future__ import annotations

import numpy as np

from quadsim.effects import make_effect

from . import sim_cases
from .crazyflow_source import (
    DRONE,
    RPM,
    FlightSpec,
    crazyflow_flights,
    crazyflow_params,
    hover_rpm,
    vehicle_params,
)
from .observe import OBSERVABLE
from .score import joined_kind

__all__ = [
    "CASES",
    "OBSERVABLE",
    "REFERENCES",
    "SOURCE",
    "case_list",
    "code_hash",
    "flight_dir",
    "generate",
    "judge",
    "library_truth",
    "load_flights",
    "oracle_reductions",
    "reference_specs",
    "shared_effects",
]

REFERENCES = 8
DURATION = 8.0
#: (truth, kind, count, speed range)
CASES = (("none", "none", 2, (0.8, 1.2)), ("none", "none", 2, (0.55, 0.65)),
         ("none", "none", 2, (1.35, 1.5)),
         ("mass_offset", "library", 2, None), ("payload", "library", 1, None),
         ("com_offset", "library", 2, None), ("inertia_error", "library", 2, None),
         ("thrust_mismatch", "library", 2, None), ("thrust_factor", "library", 1, None),
         ("motor_lag", "library", 2, None), ("rotor_drag", "library", 2, None),
         ("wind", "library", 2, None), ("rotor_delay", "library", 2, None),
         ("translational_lift", "outside", 1, None), ("blade_flapping", "outside", 1, None),
         ("periodic_torque", "outside", 2, None))
#: library name a case's truth is scored against (payload is an offset mass)
SCORED_AS = {"payload": "mass_offset"}
#: Cases flown as outside the library whose effect the library has gained since the cases
#: were frozen (blade_flapping: the same hub moment -c sum(Omega) e_z x v, c in kg m/rad, as
#: :mod:`quadsim.effects.blade_flapping`; translational_lift: 4 lift |v_h|^2 along body z,
#: :mod:`quadsim.effects.translational_lift` with k_h = lift). They are scored as in-library;
#: the flights, the case list and so the cache key are unchanged.
JOINED_LIBRARY = frozenset({"blade_flapping", "translational_lift"})


def scored_kind(case: dict) -> str:
    """The kind a case is scored as today (see :data:`JOINED_LIBRARY`)."""
    return joined_kind(case["case"], case["kind"], JOINED_LIBRARY)


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.8-1.25, seeds apart from the cases')."""
    return [FlightSpec(seed=70_000 + 31 * k, speed=0.8 + 0.064 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """Crazyflow-side effects of ``truth`` at a random realistic magnitude (module table;
    :func:`benchmarks.sim_cases.draw_effect`, with Crazyflow's own kinds: the rotor drag
    scaled, translational lift, blade flapping)."""
    cp = crazyflow_params(DRONE)
    mass, arm = float(cp["mass"]), float(np.ravel(cp["L"])[0]) * np.sqrt(2.0)
    weight = mass * 9.81
    scale = sim_cases.DrawScale(mass=mass, gravity=9.81, arm=arm, damping=0.0,
                                payload_kg=(0.004, 0.008), payload_radius=(0.005, 0.015),
                                payload_below=(0.005, 0.01), wind=(1.0, 2.5))
    own = {"rotor_drag": lambda r: {"drag_scale": r.uniform(1.5, 2.5)},
           # +2..5 % of the hover thrust at 1.5 m/s
           "translational_lift": lambda r: {"lift": r.uniform(0.02, 0.05) * weight
                                            / (4 * 1.5 ** 2)},
           # moment 2-4 % of weight x arm at 1 m/s
           "blade_flapping": lambda r: {"flap": r.uniform(0.02, 0.04) * weight * arm
                                        / (4 * hover_rpm(cp) * RPM)}}
    return sim_cases.draw_effect(truth, rng, scale, own)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the Crazyflow effects."""
    return sim_cases.draw_cases(CASES, _draw, source="crazyflow", vehicle=vehicle_params().name,
                                seed0=60_000, speeds=(0.8, 1.25), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def _rotor_rates(cp: dict, hover: float) -> tuple[float, float]:
    """Crazyflow's rotor dynamics linearised at the hover speed (RPM): 1/s up and down."""
    a = np.ravel(cp["rotor_dyn_coef"])
    return a[0] + 2 * a[1] * hover, a[2] + 2 * a[3] * hover


def shared_effects(slow: float = 1.0, drag: float = 1.0) -> list:
    """Crazyflow's nominal physics that quadsim's nominal model lacks, as library effects at
    their true values: first-order rotor dynamics (time constants 1/rate at hover, x
    ``slow``) and the body drag ``C v`` as rotor drag ``k (sum Omega) v`` with k = C / (4
    Omega_hover) (x ``drag`` in-plane)."""
    cp = crazyflow_params(DRONE)
    hover = hover_rpm(cp)
    up, down = _rotor_rates(cp, hover)
    drag_matrix = np.asarray(cp["drag_matrix"])
    per_speed = 4 * hover * RPM
    return [make_effect("motor_lag", time_constant=slow / up, time_constant_down=slow / down),
            make_effect("rotor_drag", coefficient=drag * -drag_matrix[0, 0] / per_speed,
                        axial_coefficient=-drag_matrix[2, 2] / per_speed)]


def library_truth(case: dict) -> list:
    """Library effects with the true difference of ``case`` from the references, on top of
    :func:`shared_effects` (the full effect list of the case's true model); [] for cases
    with no library form (none, outside, delay)."""
    e = case["effects"]
    shared = shared_effects(e.get("motor_slow", 1.0), e.get("drag_scale", 1.0))
    if scored_kind(case) != "library" or case["case"] == "rotor_delay":
        return []
    return shared + sim_cases.library_difference(e)   # [] for motor_slow / drag_scale:
    # the shared effects scaled


def oracle_reductions(logs: list, references: list,
                      cases: list[dict]) -> list[tuple[float, float]]:
    """Per case (reduction, gap): the cut of its flight's normalised residual (forces,
    torques, rotor channel) when the true difference is applied in quadsim's residual model
    (module docstring), and the flight's residual relative to the references' own
    (:func:`benchmarks.sim_cases.oracle_reductions` with :func:`shared_effects` and
    :func:`library_truth`)."""
    return sim_cases.oracle_reductions(logs, references, cases, vehicle_params(),
                                       shared_effects(), library_truth, scored_kind)


# ----------------------------------------------------------------------------- flights on disk

SOURCE = sim_cases.CaseSource(
    name="crazyflow", package="crazyflow",
    modules=("crazyflow_source.py", "crazyflow_worker.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=crazyflow_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)


def code_hash() -> str:
    """Hash of everything the flights depend on (:func:`benchmarks.sim_cases.code_hash`)."""
    return sim_cases.code_hash(SOURCE)


def flight_dir(cache):
    return sim_cases.flight_dir(SOURCE, cache)


def generate(cache, progress=print):
    """Fly, write and check the references and every case
    (:func:`benchmarks.sim_cases.generate`)."""
    return sim_cases.generate(SOURCE, cache, progress)


def load_flights(cache) -> tuple[list, list[dict]]:
    """(reference logs, case rows) from :func:`generate`'s folder."""
    return sim_cases.load_flights(SOURCE, cache)


def judge(cache) -> list[dict]:
    """THE BLIND RUN (:func:`benchmarks.sim_cases.judge`). Run it once, after the verdict
    rules are frozen."""
    return sim_cases.judge(SOURCE, cache)
