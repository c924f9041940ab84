"""quadcopter-sim benchmark cases: each a single flight judged per flight against 8 nominal
flights.

Source: :mod:`.qcsim_source` (quadcopter-sim 0.3.0: its own rigid-body equations and its own
0.65 kg plus-configuration vehicle; quadsim adds DC motors, a body drag, a geometric
controller and the effects quadcopter-sim has no parameter for). The cases are *frozen*:
drawn once from fixed seeds (:func:`case_list`), cached by ``benchmarks/gap_benchmark.py
--independent --source quadcopter-sim --generate-only --cache DIR`` and judged once (the same
without ``--generate-only``) with the verdict rules frozen as on main when the source was
built (6614281); the machinery is :mod:`.sim_cases`. Nothing here was tuned on how the
diagnosis does on them: the tenth source, the fourth simulator from the package index, built
after every other source's runs.

References: 8 nominal flights at path speeds 0.7-1.4 (step 0.1). Cases (28; every flight 8 s
logged at 500 Hz after a 2 s lead-in, path speed 0.75-1.35 unless stated), magnitudes drawn
uniformly (SI) by :func:`benchmarks.sim_cases.draw_effect` (vehicle 0.65 kg, arm 0.25 m,
motor time constant 21 ms at hover):

=================  =======================================  ================================
truth              change (range)                           source of the range
=================  =======================================  ================================
none x 6           nothing; 2 at speed 0.75-1.35, 2         the references' own spread
                   slower (0.45-0.55), 2 faster (1.5-1.65)
mass_offset x2     Params m +5..+20 % (33-130 g)            a camera or a larger battery
mass_offset        payload 30-100 g at 10-40 mm from the    a sensor or camera mounted off
(payload)          centre, 20-50 mm below: mass, CoM and    centre
                   the full inertia matrix (Params I)
com_offset x2      the CoM 3-10 % of the arm (7.5-25 mm)    battery placement
                   off the rotors' centre
inertia_error x2   Params I: Ixx, Iyy +15..+40 %, Izz       CAD vs pendulum inertias
                   +0..+20 %                                differ 10-40 %
thrust_mismatch    one propeller's b and d -5..-15 % (its   a chipped or bent propeller
 x2                motor then spins faster per duty)
thrust_factor      every propeller's b and d -5..-15 %      worn or different propellers
motor_lag x2       motor J x 1.5-2.5 (32-54 ms at hover     a heavier propeller
                   instead of 21)
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

Observability (:func:`oracle_reductions`): the references' shared physics that quadsim's
nominal model lacks, at its true values (:func:`shared_effects`): the body drag as
``body_drag`` (C_dA sideways 0.015 m^2, vertical 0.04 m^2; the source's drag is per body
axis, quadsim's on the speed vector) and the DC motor as ``motor_lag`` with its time
constant linearised at hover, ``J / (k_t k_e / R + 2 d Omega_h)``; a case's true difference on
top (:func:`library_truth`; a propeller change as ``thrust_factor`` with the DC motor's own
speed-per-duty exponent, :func:`motor_alpha`). A case is observable when that cuts the
flight's normalised residual by at least :data:`OBSERVABLE` (5 %); cases below it are
scored apart and marked, never dropped.

Scoring (:mod:`.score`): in-library -> a reading of the verdict names the truth (a delay:
any reading whose name contains ``delay``); no effect -> ``no_significant_gap``;
out-of-library -> no confident name.
"""

from __future__ import annotations

import numpy as np

from quadsim.effects import make_effect
from quadsim.gap.fitting import momentum_rate_damping

from . import sim_cases
from .observe import OBSERVABLE
from .qcsim_source import (
    MODEL,
    MOTOR,
    FlightSpec,
    hover_speed_of,
    qcsim_flights,
    vehicle_params,
)
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
    return [FlightSpec(seed=130_000 + 31 * k, speed=0.7 + 0.1 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """Source-side effects of ``truth`` at a random realistic magnitude (module table;
    :func:`benchmarks.sim_cases.draw_effect`)."""
    scale = sim_cases.DrawScale(
        mass=MODEL["mass"], gravity=MODEL["gravity"], arm=MODEL["arm"],
        damping=momentum_rate_damping(vehicle_params()), payload_kg=(0.03, 0.1),
        payload_radius=(0.01, 0.04), payload_below=(0.02, 0.05), hover_state=None)
    return sim_cases.draw_effect(truth, rng, scale)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the source-side effects."""
    return sim_cases.draw_cases(CASES, _draw, source="quadcopter-sim", vehicle="qcsim-plus",
                                seed0=120_000, speeds=(0.75, 1.35), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def motor_time_constant(slow: float = 1.0) -> float:
    """The DC motor's time constant (s) linearised at hover: J / (k_t k_e / R + 2 d
    Omega_h), J the motor's inertia x ``slow``."""
    return MOTOR.time_constant(hover_speed_of(), MODEL["d"], slow)


def motor_alpha(change: float) -> float:
    """The DC motor's speed-per-duty exponent of a propeller change (quadsim's
    ``thrust_factor.alpha``): the steady speed at the hover duty with d x (1 + change) is
    (1 + change)^-alpha times the nominal one."""
    return MOTOR.alpha(hover_speed_of(), MODEL["d"], change)


def shared_effects(slow: float = 1.0) -> list:
    """The source's nominal physics that quadsim's nominal model lacks, as library effects
    at their true values (module docstring): the body drag, the motor time constant (J x
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
    name="quadcopter-sim", package="quadcopter-sim",
    modules=("qcsim_source.py", "geometric.py", "flightjobs.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=qcsim_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)
