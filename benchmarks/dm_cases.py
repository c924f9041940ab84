"""drone-models benchmark cases: each a single flight judged per flight against 8 nominal
flights -- the thirteenth source, built blind (issue 47): the source, this case list and its
test were written and committed ("frozen before the first run") before quadsim's judge saw
one of its flights, and the benchmark was run once.

Source: :mod:`.dm_source` (drone-models 0.1.0's first-principles dynamics and ``cf21B_500``
parameters; this project's RK4 at 500 Hz and firmware-shaped PID cascade, :mod:`.dm_worker`;
quadsim only converts the log). Every flight 8 s logged at 500 Hz after a 3 s lead-in, path
speed 0.8-1.25 unless stated; magnitudes drawn uniformly (SI) by
:func:`benchmarks.sim_cases.draw_effect` or this module's own draws (vehicle 43.4 g, arm
50 mm: drone-models' L 35.4 mm is each rotor's x and y offset):

=================  ========================================  ================================
truth              change (range)                            source of the range
=================  ========================================  ================================
none x 6           nothing; 2 at speed 0.8-1.2, 2 slower     the references' own spread
                   (0.55-0.65), 2 faster (1.35-1.5)
mass_offset x2     mass +5..+20 % (2.2-8.7 g at the CoM)     a Crazyflie deck weighs 1.5-8 g
mass_offset        payload 4-8 g at 5-15 mm from the         a deck or marker mount off
 (payload)         centre, 5-10 mm below: mass, CoM, full    centre
                   inertia (``J``)
com_offset x2      the CoM 3-10 % of the arm (1.5-5 mm) off  battery placement
                   the rotors' centre (``dist_t``)
inertia_error x2   ``J``: Jxx, Jyy +15..+40 %, Jzz +0..+20 % CAD vs pendulum inertias of
                                                             small quads differ 10-40 %
thrust_mismatch    one rotor's ``rpm2thrust`` and            a chipped or bent propeller
 x2                ``rpm2torque`` -5..-15 %
thrust_factor      every rotor's curves -5..-15 %            worn propellers
motor_lag x2       ``rotor_dyn_coef`` / 1.5-2.5 (57 ms ->    a slower ESC/motor: time
                   85-140 ms at hover)                       constants 20-150 ms
rate_damping x2    -k w through ``dist_t``, k 1.5-3 x the    prop guards, a draggy frame
                   momentum-theory value (a third on yaw)
rotor_drag x2      ``drag_matrix`` x 1.5-2.5                 prop guards / cage
wind x2            steady wind 1-2.5 m/s, random direction,  indoor fans, outdoor calm
                   the drag matrix at the air speed
                   (``dist_f``)
rotor_delay x2     the rotor-speed log 10-30 ms late         ESC telemetry 10-30 ms
outside x 2        a 1-3 Hz roll/pitch torque 1-3 % of       a cable or loose part tugging;
 (x1 each)         weight x arm (``dist_t``); a 2-5 Hz       a loose deck bouncing
                   body-z force 1-3 % of the weight
                   (``dist_f``)
=================  ========================================  ================================

Observability (:func:`oracle_reductions`): the references' shared physics that quadsim's
nominal model lacks, at its true values (:func:`shared_effects`): drone-models' rotor
dynamics linearised at hover as ``motor_lag`` (57 ms up, 62 ms down), its drag matrix as
``rotor_drag`` (k (sum Omega) v with k = C / (4 Omega_hover)) and the thrust curve's linear
term as ``thrust_curve`` (its N/RPM in N s/rad); a case's true difference on top
(:func:`library_truth`). The torque curve's linear term (+4.2 % of the hover torque) and
drone-models' propeller gyroscopic torque have no library form here and stay in the
residual. A case is observable when the true difference cuts the flight's normalised
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
from .dm_source import RPM, FlightSpec, dm_flights, dm_params, hover_rpm, vehicle_params
from .observe import OBSERVABLE
from .score import joined_kind

__all__ = ["CASES", "OBSERVABLE", "REFERENCES", "SCORED_AS", "SOURCE", "case_list",
           "case_spec", "library_truth", "oracle_reductions", "reference_specs",
           "scored_kind", "shared_effects"]

REFERENCES = 8
DURATION = 8.0
#: (truth, kind, count, speed range or None): the module table, 28 cases
CASES = (("none", "none", 2, (0.8, 1.2)), ("none", "none", 2, (0.55, 0.65)),
         ("none", "none", 2, (1.35, 1.5)),
         ("mass_offset", "library", 2, None), ("payload", "library", 1, None),
         ("com_offset", "library", 2, None), ("inertia_error", "library", 2, None),
         ("thrust_mismatch", "library", 2, None), ("thrust_factor", "library", 1, None),
         ("motor_lag", "library", 2, None), ("rate_damping", "library", 2, None),
         ("rotor_drag", "library", 2, None), ("wind", "library", 2, None),
         ("rotor_delay", "library", 2, None),
         ("periodic_torque", "outside", 1, None), ("periodic_force", "outside", 1, None))
#: library name a case's truth is scored against (a payload is an offset mass)
SCORED_AS = {"payload": "mass_offset"}
#: cases flown as outside the library whose effect the library has gained since (none)
JOINED_LIBRARY: frozenset = frozenset()


def scored_kind(case: dict) -> str:
    """The kind a case is scored as today (see :data:`JOINED_LIBRARY`)."""
    return joined_kind(case["case"], case["kind"], JOINED_LIBRARY)


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.8-1.25, seeds apart from the cases')."""
    return [FlightSpec(seed=180_000 + 31 * k, speed=0.8 + 0.064 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _arm() -> float:
    """Rotor distance from the centre (m): drone-models' L is each rotor's x and y offset."""
    return float(dm_params()["L"]) * np.sqrt(2.0)


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """Source-side effects of ``truth`` at a random realistic magnitude (module table)."""
    p = dm_params()
    scale = sim_cases.DrawScale(
        mass=float(p["mass"]), gravity=-float(p["gravity_vec"][2]), arm=_arm(),
        damping=momentum_rate_damping(vehicle_params()), payload_kg=(0.004, 0.008),
        payload_radius=(0.005, 0.015), payload_below=(0.005, 0.01), wind=(1.0, 2.5))
    own = {"rotor_drag": lambda r: {"drag_scale": r.uniform(1.5, 2.5)}}
    return sim_cases.draw_effect(truth, rng, scale, own)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the source-side effects."""
    return sim_cases.draw_cases(CASES, _draw, source="drone-models",
                                vehicle=vehicle_params().name, seed0=170_000,
                                speeds=(0.8, 1.25), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def _rotor_rates(hover: float) -> tuple[float, float]:
    """drone-models' rotor dynamics linearised at ``hover`` RPM: 1/s up and down
    (c1 + 2 c2 Omega and c3 + 2 c4 Omega)."""
    a = np.ravel(dm_params()["rotor_dyn_coef"])
    return a[0] + 2 * a[1] * hover, a[2] + 2 * a[3] * hover


def shared_effects(slow: float = 1.0, drag: float = 1.0) -> list:
    """drone-models' nominal physics that quadsim's nominal model lacks, as library effects at
    their true values (module doc): its rotor dynamics at hover (time constants x ``slow``),
    its drag matrix (x ``drag``) as rotor drag, its thrust curve's linear term."""
    p = dm_params()
    hover = hover_rpm()
    up, down = _rotor_rates(hover)
    per_speed = 4 * hover * RPM
    d = np.asarray(p["drag_matrix"])
    return [make_effect("motor_lag", time_constant=slow / up, time_constant_down=slow / down),
            make_effect("rotor_drag", coefficient=drag * -d[0, 0] / per_speed,
                        axial_coefficient=drag * -d[2, 2] / per_speed),
            make_effect("thrust_curve", linear=float(p["rpm2thrust"][1]) / RPM)]


def library_truth(case: dict) -> list:
    """Library effects with the true difference of ``case`` from the references on top of
    :func:`shared_effects` (the case's true model; a propeller change with exponent 0: the
    rotor speed follows the command whatever the propeller); [] for cases with no library
    form (none, outside) and for a late rotor log."""
    e = case["effects"]
    if scored_kind(case) != "library" or "rotor_delay" in e:
        return []
    # [] for motor_slow / drag_scale: the shared effects scaled
    return (shared_effects(e.get("motor_slow", 1.0), e.get("drag_scale", 1.0))
            + sim_cases.library_difference(e, rate_damping=True))


def oracle_reductions(logs: list, references: list,
                      cases: list[dict]) -> list[tuple[float, float]]:
    """Per case (reduction, gap ratio): :func:`benchmarks.sim_cases.oracle_reductions` with
    :func:`shared_effects` and :func:`library_truth`."""
    return sim_cases.oracle_reductions(logs, references, cases, vehicle_params(),
                                       shared_effects(), library_truth, scored_kind)


SOURCE = sim_cases.CaseSource(
    name="drone-models", package="drone-models",
    modules=("dm_source.py", "dm_worker.py", "flightjobs.py", "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=dm_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)
