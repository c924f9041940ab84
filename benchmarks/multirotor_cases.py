"""multirotor benchmark cases: each a single flight judged per flight against 8 nominal flights.

Source: :mod:`.multirotor_source` (multirotor 0.5.0: its own rigid body, DC motors and
cascaded PID; a 5.5 kg heavy-lift quadrotor X with its Tarot T18 motor and 18-inch
propeller; quadsim adds only a body drag and the effects multirotor has no parameter for).
The cases are *frozen*: drawn once from fixed seeds (:func:`case_list`), cached by
``benchmarks/gap_benchmark.py --independent --source multirotor --generate-only --cache DIR``
and judged once (the same without ``--generate-only``) with the verdict rules frozen as on
main when the source was built; the machinery is :mod:`.sim_cases`, shared with the Crazyflow
and PyFlyt sources. Nothing here was tuned on how the diagnosis does on them: the third
source that the project has not seen, built after the Crazyflow and PyFlyt blind runs.

References: 8 nominal flights at path speeds 0.7-1.4 (step 0.1). Cases (28; every flight 8 s
logged at 500 Hz after a 2 s lead-in, path speed 0.75-1.35 unless stated), magnitudes drawn
uniformly (SI) in multirotor's terms (vehicle 5.5 kg, arm 0.45 m, motor time constant about 5
ms at hover):

=================  =======================================  ================================
truth              multirotor change (range)                source of the range
=================  =======================================  ================================
none x 6           nothing; 2 at speed 0.75-1.35, 2         the references' own spread
                   slower (0.45-0.55), 2 faster (1.5-1.65)
mass_offset x2     VehicleParams mass +5..+20 %             a camera or a larger battery
                   (0.28-1.1 kg)
mass_offset        payload 0.2-0.6 kg at 20-60 mm from the  a gimbal or sensor mounted off
(payload)          centre, 30-80 mm below: mass, CoM and    centre
                   the full inertia matrix
com_offset x2      the propellers' positions about the CoM  battery placement (the range
                   moved by 3-10 % of the arm (13-45 mm)    of the other sources' cases)
inertia_error x2   inertia matrix Ixx, Iyy +15..+40 %,      CAD vs pendulum inertias
                   Izz +0..+20 %                            differ 10-40 %
thrust_mismatch    one propeller's k_thrust and k_drag      a chipped or bent propeller;
 x2                -5..-15 % (its motor then spins faster   multirotor's motor feels the
                   per volt: less load torque)              lighter load
thrust_factor      every propeller's k_thrust and k_drag    worn or different propellers
                   -5..-15 %
motor_lag x2       motor J x 1.5-2.5 (a time constant of    a heavier motor bell or
                   7-13 ms at hover instead of 5)           propeller
rate_damping x2    a torque -k w, k (1.5..3) x the          prop guards add frame drag
                   momentum-theory damping on roll and      (quadsim.gap.fitting)
                   pitch, a third of it on yaw
wind x2            steady wind 2-5 m/s, random direction,   outdoor breeze (Beaufort 2-3)
                   through the body drag
rotor_delay x2     rotor-speed log 10-30 ms late            ESC telemetry 10-30 ms
outside x 4        a 1-3 Hz roll/pitch torque 1-3 % of      a cable or loose part tugging;
 (x2 each)         weight x arm; a 2-5 Hz vertical force    a loose gimbal or landing gear
                   1-3 % of the weight                      bouncing
=================  =======================================  ================================

Observability (:func:`oracle_reductions`, :func:`benchmarks.sim_cases.oracle_reductions`):
the references' shared physics that quadsim's nominal model lacks, at its true values
(:func:`shared_effects`): the body drag as ``body_drag`` (C_dA sideways 0.05 m^2, vertical
0.12 m^2; the source's drag is per body axis, quadsim's on the speed vector) and the DC motor
as ``motor_lag`` with its time constant linearised at hover, ``J / (k_t k_e / R + 2 k_d
Omega_h)``; a case's true difference on top (:func:`library_truth`; a propeller change as
``thrust_factor`` with the DC motor's own speed-per-command exponent, :func:`motor_alpha`). A
case is observable when that cuts the flight's normalised residual by at least
:data:`OBSERVABLE` (5 %); cases below it are scored apart and marked, never dropped.

Scoring (:mod:`.score`): in-library -> a reading of the verdict names the truth (a delay:
any reading whose name contains ``delay``); no effect -> ``no_significant_gap``;
out-of-library -> no confident name.
"""

from __future__ import annotations

import numpy as np

from quadsim.effects import make_effect
from quadsim.gap.fitting import momentum_rate_damping

from . import sim_cases
from .multirotor_source import (
    MODEL,
    FlightSpec,
    hover_speed_of,
    multirotor_flights,
    steady_speed,
    vehicle_params,
)
from .observe import OBSERVABLE
from .score import joined_kind

__all__ = ["CASES", "OBSERVABLE", "REFERENCES", "SOURCE", "case_list", "case_spec",
           "library_truth", "motor_alpha", "motor_time_constant", "oracle_reductions",
           "reference_specs", "shared_effects"]

REFERENCES = 8
DURATION = 8.0
#: (truth, kind, count, speed range): the table of the DC-motor sources
CASES = sim_cases.MOTOR_TABLE
#: library name a case's truth is scored against (payload is an offset mass)
SCORED_AS = sim_cases.PAYLOAD_AS_MASS
#: cases flown as outside the library whose effect the library has gained since (none yet)
JOINED_LIBRARY: frozenset = frozenset()


def scored_kind(case: dict) -> str:
    """The kind a case is scored as today (see :data:`JOINED_LIBRARY`)."""
    return joined_kind(case["case"], case["kind"], JOINED_LIBRARY)


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.7-1.4, seeds apart from the cases')."""
    return [FlightSpec(seed=70_000 + 31 * k, speed=0.7 + 0.1 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """multirotor-side effects of ``truth`` at a random realistic magnitude (module table;
    :func:`benchmarks.sim_cases.draw_effect`)."""
    scale = sim_cases.DrawScale(
        mass=MODEL["mass"], gravity=MODEL["gravity"], arm=MODEL["arm"],
        damping=momentum_rate_damping(vehicle_params()), payload_kg=(0.2, 0.6),
        payload_radius=(0.02, 0.06), payload_below=(0.03, 0.08), hover_state=None)
    return sim_cases.draw_effect(truth, rng, scale)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the multirotor effects."""
    return sim_cases.draw_cases(CASES, _draw, source="multirotor", vehicle="multirotor-x4",
                                seed0=60_000, speeds=(0.75, 1.35), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def motor_time_constant(slow: float = 1.0) -> float:
    """The DC motor's time constant (s) linearised at hover: J / (k_t k_e / R + 2 k_d
    Omega_h), J the motor's inertia x ``slow``."""
    m = MODEL
    hover = hover_speed_of()
    return float(m["motor_inertia"] * slow / (m["k_emf"] ** 2 / m["resistance"]
                                              + 2 * m["k_drag"] * hover))


def motor_alpha(change: float) -> float:
    """The DC motor's speed-per-command exponent of a propeller change (quadsim's
    ``thrust_factor.alpha``): the steady speed at the hover command with k_d x (1 +
    change) is (1 + change)^-alpha times the nominal one."""
    hover = hover_speed_of()
    grid = np.linspace(0.0, 1.0, 2001)
    command = float(np.interp(hover, steady_speed(grid), grid))
    ratio = float(steady_speed(np.array([command]), MODEL["k_drag"] * (1 + change))[0]
                  / steady_speed(np.array([command]))[0])
    return float(np.clip(-np.log(ratio) / np.log1p(change), 0.0, 0.5))


def shared_effects(slow: float = 1.0) -> list:
    """multirotor's nominal physics that quadsim's nominal model lacks, as library effects at
    their true values (module docstring): the body drag, the motor time constant (J x
    ``slow``)."""
    cd = MODEL["cd_area"]
    return [make_effect("motor_lag", time_constant=motor_time_constant(slow)),
            make_effect("body_drag", cd_area=cd[0], cd_area_vertical=cd[2])]


def library_truth(case: dict) -> list:
    """Library effects with the true difference of ``case`` from the references, on top of
    :func:`shared_effects` (the full effect list of the case's true model); [] for cases
    with no library form (none, outside, delay):
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
    name="multirotor", package="multirotor",
    modules=("multirotor_source.py", "flightjobs.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=multirotor_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)
