"""l2f benchmark cases: each a single flight judged per flight against 8 nominal flights.

Source: :mod:`.l2f_source` (l2f 2.0.18, RLtools' "Learning to Fly" simulator: its own
single-precision RK4 rigid body, first-order rotor model and identified Holybro X500, 2.0
kg; this project adds only a body drag, the effects l2f has no parameter for, and a PID
cascade: l2f ships none). The cases are *frozen*: drawn once from fixed seeds
(:func:`case_list`), cached by ``scripts/gap_benchmark.py --independent --source l2f
--generate-only --cache DIR`` and judged once (the same without ``--generate-only``) with
the verdict rules frozen as on main when the source was built (c5584aa); the machinery is
:mod:`.sim_cases`, shared with the Crazyflow, PyFlyt and multirotor sources. Nothing here
was tuned on how the diagnosis does on them: the fourth source the project has not seen,
built after the multirotor blind run.

References: 8 nominal flights at path speeds 0.7-1.4 (step 0.1). Cases (30; every flight 8 s
logged at 500 Hz after a 2 s lead-in, path speed 0.75-1.35 unless stated), magnitudes drawn
uniformly (SI) in l2f's terms (vehicle 2.0 kg, arm 0.25 m, hover thrust 4.9 N per rotor at
a rotor state of 0.555, rotor time constant 54 ms):

=================  =======================================  ================================
truth              l2f change (range)                       source of the range
=================  =======================================  ================================
none x 6           nothing; 2 at speed 0.75-1.35, 2         the references' own spread
                   slower (0.45-0.55), 2 faster (1.5-1.65)
mass_offset x2     mass +5..+20 % (0.1-0.4 kg)              a camera or a larger battery
mass_offset        payload 0.1-0.3 kg at 20-50 mm from the  a gimbal or sensor mounted off
(payload)          centre, 20-60 mm below: mass, CoM and    centre
                   the full inertia matrix
com_offset x2      the rotors' positions about the CoM      battery placement (the range
                   moved by 3-10 % of the arm (7.5-25 mm)   of the other sources' cases)
inertia_error x2   J (and J^-1) Ixx, Iyy +15..+40 %, Izz    CAD vs pendulum inertias
                   +0..+20 %                                differ 10-40 %
thrust_mismatch    one rotor's thrust coefficients          a chipped or bent propeller
 x2                -5..-15 % (its reaction torque follows)
thrust_factor      every rotor's -5..-15 %                  worn or different propellers
thrust_curve x2    a linear thrust term c1 a, c1 a_hover    a propeller whose stand fit has
                   +-5..15 % of the hover thrust (random    a linear term (Foerster 2015,
                   sign)                                    table 3.3; the 2015 report)
motor_lag x2       both rotor time constants x 1.5-2.5      slower ESC or heavier propeller
                   (81-135 ms instead of 54)
rate_damping x2    a torque -k w, k (1.5..3) x the          prop guards add frame drag
                   momentum-theory damping on roll and      (quadsim.gap.priors)
                   pitch, a third of it on yaw
wind x2            steady wind 2-5 m/s, random direction,   outdoor breeze (Beaufort 2-3)
                   through the body drag
rotor_delay x2     rotor-speed log 10-30 ms late            ESC telemetry 10-30 ms
outside x 4        a 1-3 Hz roll/pitch torque 1-3 % of      a cable or loose part tugging;
 (x2 each)         weight x arm; a 2-5 Hz vertical force    a loose gimbal or landing gear
                   1-3 % of the weight                      bouncing
=================  =======================================  ================================

Observability (:func:`oracle_reductions`, :func:`quadsim.bench.sim_cases.oracle_reductions`):
the references' shared physics that quadsim's nominal model lacks, at its true values
(:func:`shared_effects`): the body drag as ``body_drag`` (C_dA sideways 0.02 m^2, vertical
0.05 m^2; the source's drag is per body axis, quadsim's on the speed vector) and the rotor
model as ``motor_lag`` (54 ms); a case's true difference on top (:func:`library_truth`; a
propeller change as ``thrust_factor`` with no speed-per-command change, alpha 0: l2f's rotor
state follows its command whatever the load; a linear term as ``thrust_curve`` with
``linear = c1 / OMEGA_MAX``). A case is observable when that cuts the flight's normalised
residual by at least :data:`OBSERVABLE` (5 %); cases below it are scored apart and marked,
never dropped.

Scoring (:mod:`.score`): in-library -> a reading of the verdict names the truth (a delay:
any reading whose name contains ``delay``); no effect -> ``no_significant_gap``;
out-of-library -> no confident name.
"""

from __future__ import annotations

import numpy as np

from ..effects import make_effect
from ..gap.priors import momentum_rate_damping
from . import sim_cases
from .l2f_source import (MODEL, OMEGA_MAX, FlightSpec, hover_command, l2f_flights,
                         vehicle_params)
from .observe import OBSERVABLE
from .score import joined_kind

__all__ = ["CASES", "OBSERVABLE", "REFERENCES", "SOURCE", "case_list", "case_spec",
           "library_truth", "oracle_reductions", "reference_specs", "shared_effects"]

REFERENCES = 8
DURATION = 8.0
ARM = 0.25
#: (truth, kind, count, speed range)
CASES = (("none", "none", 2, (0.75, 1.35)), ("none", "none", 2, (0.45, 0.55)),
         ("none", "none", 2, (1.5, 1.65)),
         ("mass_offset", "library", 2, None), ("payload", "library", 1, None),
         ("com_offset", "library", 2, None), ("inertia_error", "library", 2, None),
         ("thrust_mismatch", "library", 2, None), ("thrust_factor", "library", 1, None),
         ("thrust_curve", "library", 2, None),
         ("motor_lag", "library", 2, None), ("rate_damping", "library", 2, None),
         ("wind", "library", 2, None), ("rotor_delay", "library", 2, None),
         ("periodic_torque", "outside", 2, None), ("periodic_force", "outside", 2, None))
#: library name a case's truth is scored against (payload is an offset mass)
SCORED_AS = {"payload": "mass_offset"}
#: cases flown as outside the library whose effect the library has gained since (none yet)
JOINED_LIBRARY: frozenset = frozenset()


def scored_kind(case: dict) -> str:
    """The kind a case is scored as today (see :data:`JOINED_LIBRARY`)."""
    return joined_kind(case["case"], case["kind"], JOINED_LIBRARY)


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.7-1.4, seeds apart from the cases')."""
    return [FlightSpec(seed=90_000 + 37 * k, speed=0.7 + 0.1 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """l2f-side effects of ``truth`` at a random realistic magnitude (module table;
    :func:`quadsim.bench.sim_cases.draw_effect`)."""
    scale = sim_cases.DrawScale(
        mass=MODEL["mass"], gravity=MODEL["gravity"], arm=ARM,
        damping=momentum_rate_damping(vehicle_params()), payload_kg=(0.1, 0.3),
        payload_radius=(0.02, 0.05), payload_below=(0.02, 0.06), hover_state=hover_command())
    return sim_cases.draw_effect(truth, rng, scale)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the l2f effects."""
    return sim_cases.draw_cases(CASES, _draw, source="l2f", vehicle="l2f-x500",
                                seed0=80_000, speeds=(0.75, 1.35), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def shared_effects(slow: float = 1.0) -> list:
    """l2f's nominal physics that quadsim's nominal model lacks, as library effects at their
    true values (module docstring): the rotor time constant (x ``slow``), the body drag."""
    cd = MODEL["cd_area"]
    return [make_effect("motor_lag", time_constant=MODEL["tau"] * slow),
            make_effect("body_drag", cd_area=cd[0], cd_area_vertical=cd[2])]


def library_truth(case: dict) -> list:
    """Library effects with the true difference of ``case`` from the references, on top of
    :func:`shared_effects` (the full effect list of the case's true model); [] for cases
    with no library form (none, outside, delay)."""
    e = case["effects"]
    shared = shared_effects(e.get("motor_slow", 1.0))
    if scored_kind(case) != "library" or "rotor_delay" in e:
        return []
    # [] for motor_slow: the shared rotor lag scaled; alpha 0 (module doc)
    return shared + sim_cases.library_difference(e, linear_per_speed=1.0 / OMEGA_MAX,
                                                 rate_damping=True)


def oracle_reductions(logs: list, references: list,
                      cases: list[dict]) -> list[tuple[float, float]]:
    """Per case (reduction, gap ratio): :func:`quadsim.bench.sim_cases.oracle_reductions`
    with :func:`shared_effects` and :func:`library_truth`."""
    return sim_cases.oracle_reductions(logs, references, cases, vehicle_params(),
                                       shared_effects(), library_truth, scored_kind)


SOURCE = sim_cases.CaseSource(
    name="l2f", package="l2f",
    modules=("l2f_source.py", "flightjobs.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=l2f_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)
