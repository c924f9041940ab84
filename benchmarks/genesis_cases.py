"""Genesis benchmark cases: each a single flight judged per flight against 8 nominal flights.

Source: :mod:`.genesis_source` (Genesis 1.4.5: its own rigid-body solver and its own 0.83 kg
racer, ``racer.urdf``; quadsim adds DC motors, the file's rotor drag, a geometric controller
and the effects Genesis has no parameter for). The cases are *frozen*: drawn once from fixed
seeds (:func:`case_list`), cached by ``benchmarks/gap_benchmark.py --independent --source genesis
--generate-only --cache DIR`` and judged once (the same without ``--generate-only``) with the
verdict rules frozen as on main when the source was built; the machinery is
:mod:`.sim_cases`. Nothing here was tuned on how the diagnosis does on them: the eleventh
source, the fifth simulator from the package index, built after every other source's runs.

References: 8 nominal flights at path speeds 0.7-1.4 (step 0.1). Cases: the table of
:mod:`.qcsim_cases` (28; every flight 8 s logged at 500 Hz after a 2 s lead-in), magnitudes
drawn uniformly (SI) by :func:`benchmarks.sim_cases.draw_effect` against this vehicle
(0.83 kg, arm 0.108 m, motor time constant 34 ms at hover; a payload 40-120 g at 10-40 mm
from the centre, 20-50 mm below).

Observability (:func:`oracle_reductions`): the references' shared physics that quadsim's
nominal model lacks, at its true values (:func:`shared_effects`): the file's rotor drag as
``rotor_drag`` (in-plane and axial coefficients k_xy, k_z: the same form) and the DC motor
as ``motor_lag`` with its time constant linearised at hover; a case's true difference on top
(:func:`library_truth`; a propeller change as ``thrust_factor`` with the DC motor's own
speed-per-duty exponent). A case is observable when that cuts the flight's normalised
residual by at least :data:`OBSERVABLE` (5 %); cases below it are scored apart and marked,
never dropped.

Scoring (:mod:`.score`): in-library -> a reading of the verdict names the truth (a delay:
any reading whose name contains ``delay``); no effect -> ``no_significant_gap``;
out-of-library -> no confident name.
"""

from __future__ import annotations

import numpy as np

from quadsim.effects import make_effect
from quadsim.gap.fitting import momentum_rate_damping

from . import sim_cases
from .genesis_source import (
    MODEL,
    MOTOR,
    FlightSpec,
    genesis_flights,
    genesis_version,
    hover_speed_of,
    vehicle_params,
)
from .observe import OBSERVABLE
from .qcsim_cases import CASES, DURATION, REFERENCES, SCORED_AS, case_spec, scored_kind

__all__ = ["CASES", "OBSERVABLE", "REFERENCES", "SOURCE", "case_list", "case_spec",
           "library_truth", "motor_alpha", "motor_time_constant", "oracle_reductions",
           "reference_specs", "shared_effects"]


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.7-1.4, seeds apart from the cases')."""
    return [FlightSpec(seed=150_000 + 31 * k, speed=0.7 + 0.1 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _arm() -> float:
    return float(np.hypot(*MODEL["positions"][0]))


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """Source-side effects of ``truth`` at a random realistic magnitude
    (:func:`benchmarks.sim_cases.draw_effect`)."""
    scale = sim_cases.DrawScale(
        mass=MODEL["mass"], gravity=MODEL["gravity"], arm=_arm(),
        damping=momentum_rate_damping(vehicle_params()), payload_kg=(0.04, 0.12),
        payload_radius=(0.01, 0.04), payload_below=(0.02, 0.05), hover_state=None)
    return sim_cases.draw_effect(truth, rng, scale)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the source-side effects."""
    return sim_cases.draw_cases(CASES, _draw, source="genesis", vehicle="genesis-racer",
                                seed0=140_000, speeds=(0.75, 1.35), scored_as=SCORED_AS)


def motor_time_constant(slow: float = 1.0) -> float:
    """The DC motor's time constant (s) linearised at hover, J x ``slow``."""
    return MOTOR.time_constant(hover_speed_of(), MODEL["d"], slow)


def motor_alpha(change: float) -> float:
    """The DC motor's speed-per-duty exponent of a propeller change at the hover duty."""
    return MOTOR.alpha(hover_speed_of(), MODEL["d"], change)


def shared_effects(slow: float = 1.0) -> list:
    """The source's nominal physics that quadsim's nominal model lacks, as library effects
    at their true values (module docstring): the motor time constant (J x ``slow``), the
    file's rotor drag."""
    return [make_effect("motor_lag", time_constant=motor_time_constant(slow)),
            make_effect("rotor_drag", coefficient=MODEL["drag_xy"],
                        axial_coefficient=MODEL["drag_z"])]


def library_truth(case: dict) -> list:
    """Library effects with the true difference of ``case`` from the references, on top of
    :func:`shared_effects`; [] for cases with no library form (none, outside, delay):
    :func:`benchmarks.sim_cases.motor_library_truth`."""
    return sim_cases.motor_library_truth(
        case, shared_effects(case["effects"].get("motor_slow", 1.0)), motor_alpha,
        scored_kind(case))


def oracle_reductions(logs: list, references: list,
                      cases: list[dict]) -> list[tuple[float, float]]:
    """Per case (reduction, gap ratio): :func:`benchmarks.sim_cases.oracle_reductions`
    with :func:`shared_effects` and :func:`library_truth`."""
    return sim_cases.oracle_reductions(logs, references, cases, vehicle_params(),
                                       shared_effects(), library_truth, scored_kind)


SOURCE = sim_cases.CaseSource(
    name="genesis", package="genesis-world",
    modules=("genesis_source.py", "genesis_worker.py", "geometric.py", "qcsim_source.py",
             "flightjobs.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=genesis_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE, version=genesis_version)
