"""Robotics Toolbox for Python benchmark cases: each a single flight judged per flight against
8 nominal flights -- the nineteenth source, built blind (issue 47): the source, this case list
and its test were written and committed ("frozen before the first run") before quadsim's
judge saw one of its flights, and the benchmark was run once.

Source: :mod:`.rtb_source` (roboticstoolbox-python 1.5.0: the ``MultiRotor`` block's
dynamics -- Pounds & Corke's X-4 Flyer with rotor flapping, NED, ZYX Euler angles -- and its
default 4 kg vehicle; this project's RK4, first-order motor, geometric controller, path,
added loads and frame conversion). Every flight 8 s logged at 500 Hz after a 3 s lead-in,
path speed 0.8-1.25 unless stated; magnitudes drawn uniformly (SI) by
:func:`benchmarks.sim_cases.draw_effect` or this module's own draws (vehicle 4.0 kg, arm
0.315 m):

=================  ========================================  ================================
truth              change (range)                            source of the range
=================  ========================================  ================================
none x 6           nothing; 2 at speed 0.8-1.2, 2 slower     the references' own spread
                   (0.55-0.65), 2 faster (1.35-1.5)
mass_offset x2     mass +5..+20 % (0.2-0.8 kg at the CoM)    a camera or battery swap
mass_offset        payload 0.2-0.6 kg at 30-100 mm from the  a camera or gimbal mount off
 (payload)         centre, 20-80 mm below: mass, CoM, full   centre
                   inertia (the model's ``M``, ``J``)
com_offset x2      the CoM 3-10 % of the arm (9-32 mm) off   battery placement
                   the rotors' centre (the hubs' ``D``)
inertia_error x2   Ixx, Iyy +15..+40 %, Izz +0..+20 %        CAD vs pendulum inertias differ
                                                             10-40 %
thrust_mismatch    one rotor -5..-15 % (its speed passed as  a chipped or bent propeller
 x2                sqrt(1 + change) Omega: the block has one
                   ``Ct``)
thrust_factor      every rotor's ``Ct`` and ``Cq`` -5..-15 % worn propellers
motor_lag x2       the motor time constant x 1.5-2.5 (40 ms  ESC/motor time constants
                   -> 60-100 ms)                             20-150 ms
rate_damping x2    -k w, k 1.5-3 x the momentum-theory       prop guards, a draggy frame
                   value (a third on yaw)
rotor_drag x2      the flapping's blade angles ``theta0``,   stiffer or softer blades, guards
                   ``theta1`` x 1.5-2.5 (the block's only    (the block has no frame drag)
                   drag, its flapping force, x that)
wind x2            steady wind 1-3 m/s, random direction     indoor fans, outdoor calm
                   (the block's air velocity v - wind)
rotor_delay x2     the rotor-speed log 10-30 ms late         ESC telemetry 10-30 ms
outside x 2        a 1-3 Hz roll/pitch torque 1-3 % of       a cable or loose part tugging;
 (x1 each)         weight x arm; a 2-5 Hz body-z force 1-3 % a loose deck bouncing
                   of the weight
=================  ========================================  ================================

Observability (:func:`oracle_reductions`): the references' shared physics that quadsim's
nominal model lacks, at its true values (:func:`shared_effects`): the motor lag as
``motor_lag`` (40 ms, x ``motor_slow``) and the flapping's in-plane force as ``rotor_drag``
(:func:`benchmarks.rtb_source.flap_coefficient` per rotor, x ``drag_scale``; nothing along
the axis: the block's thrust does not change with inflow); a case's true difference on top
(:func:`library_truth`). The block's flapping on the body rates (a force of 0.27 N per rad/s
at hover) and its world velocity read in body axes (the flapping drag turned by the yaw) have
no library form and stay in the residual. A case is observable when the true difference cuts
the flight's normalised residual by at least :data:`OBSERVABLE` (5 %); cases below it are
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
from .dsim_cases import CASES, JOINED_LIBRARY, SCORED_AS, scored_kind
from .observe import OBSERVABLE
from .rtb_source import (
    MOTOR_TAU,
    FlightSpec,
    flap_coefficient,
    rtb_flights,
    rtb_model,
    vehicle_params,
)

__all__ = ["CASES", "JOINED_LIBRARY", "OBSERVABLE", "REFERENCES", "SCORED_AS", "SOURCE",
           "case_list", "case_spec", "library_truth", "oracle_reductions", "reference_specs",
           "scored_kind", "shared_effects"]

REFERENCES = 8
DURATION = 8.0


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.8-1.25, seeds apart from the cases')."""
    return [FlightSpec(seed=400_000 + 31 * k, speed=0.8 + 0.064 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """Source-side effects of ``truth`` at a random realistic magnitude (module table)."""
    q = rtb_model()
    scale = sim_cases.DrawScale(
        mass=q["M"], gravity=q["g"], arm=q["d"],
        damping=momentum_rate_damping(vehicle_params()), payload_kg=(0.2, 0.6),
        payload_radius=(0.03, 0.1), payload_below=(0.02, 0.08), wind=(1.0, 3.0))
    own = {"rotor_drag": lambda r: {"drag_scale": r.uniform(1.5, 2.5)}}
    return sim_cases.draw_effect(truth, rng, scale, own)


def case_list() -> list[dict]:
    """The frozen cases (the table of :mod:`.dsim_cases`, its 28 rows, drawn for this
    vehicle): truth (scored name), kind, seed, speed and the source-side effects."""
    return sim_cases.draw_cases(CASES, _draw, source="roboticstoolbox",
                                vehicle=vehicle_params().name, seed0=390_000,
                                speeds=(0.8, 1.25), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def shared_effects(slow: float = 1.0, drag: float = 1.0) -> list:
    """The nominal physics quadsim's nominal model lacks, as library effects at their true
    values (module doc): the motor lag (40 ms x ``slow``) and the flapping force (x
    ``drag``) as in-plane rotor drag."""
    return [make_effect("motor_lag", time_constant=slow * MOTOR_TAU),
            make_effect("rotor_drag", coefficient=drag * flap_coefficient(),
                        axial_coefficient=0.0)]


def library_truth(case: dict) -> list:
    """Library effects with the true difference of ``case`` from the references on top of
    :func:`shared_effects` (the case's true model; a thrust change with exponent 0: the
    rotor speed follows the command whatever the propeller); [] for cases with no library
    form (none, outside) and for a late rotor log."""
    e = case["effects"]
    if scored_kind(case) != "library" or "rotor_delay" in e:
        return []
    # [] from library_difference for motor_slow / drag_scale: the shared effects scaled
    return (shared_effects(e.get("motor_slow", 1.0), e.get("drag_scale", 1.0))
            + sim_cases.library_difference(e, rate_damping=True))


def oracle_reductions(logs: list, references: list,
                      cases: list[dict]) -> list[tuple[float, float]]:
    """Per case (reduction, gap ratio): :func:`benchmarks.sim_cases.oracle_reductions` with
    :func:`shared_effects` and :func:`library_truth`."""
    return sim_cases.oracle_reductions(logs, references, cases, vehicle_params(),
                                       shared_effects(), library_truth, scored_kind)


SOURCE = sim_cases.CaseSource(
    name="roboticstoolbox", package="roboticstoolbox-python",
    modules=("rtb_source.py", "dsim_source.py", "flightjobs.py", "geometric.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=rtb_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)
