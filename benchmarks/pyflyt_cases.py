"""PyFlyt benchmark cases: each a single flight judged per flight against 8 nominal PyFlyt flights.

Source: :mod:`.pyflyt_source` (PyFlyt 0.29.0's QuadX ``cf2x`` in pybullet: its own motors,
drag, rate damping and PID cascade; quadsim only converts the log). The cases are *frozen*:
drawn once from fixed seeds (:func:`case_list`), cached by ``benchmarks/gap_benchmark.py
--independent --source pyflyt --generate-only --cache DIR`` and judged once (the same
without ``--generate-only``) after the verdict rules are frozen; the machinery is
:mod:`.sim_cases`, shared with the Crazyflow source. Nothing here was tuned on how the
diagnosis does on them.

References: 8 nominal flights at path speeds 0.7-1.4 (step 0.1). Cases (28; every flight 8 s
logged at 240 Hz after a 2 s lead-in, path speed 0.75-1.35 unless stated), magnitudes drawn
uniformly (SI) in PyFlyt's own terms (vehicle 27 g, arm 39.6 mm, tau 10 ms):

=================  =======================================  ================================
truth              PyFlyt change (range)                    source of the range
=================  =======================================  ================================
none x 6           nothing; 2 at speed 0.75-1.35, 2         the references' own spread
                   slower (0.45-0.55), 2 faster (1.5-1.65)
mass_offset x2     URDF mass +5..+20 % (1.4-5.4 g)           a deck or a heavier battery:
                                                            Crazyflie decks weigh 1.5-8 g
mass_offset        payload 2-5 g at 5-15 mm from the         a deck or marker mount off
(payload)          centre, 5-10 mm below: URDF mass, CoM     centre
                   and principal inertia
com_offset x2      URDF inertial origin 3-10 % of the arm    battery placement (the range
                   (1.2-4.0 mm)                             of the other sources' cases)
inertia_error x2   URDF Ixx, Iyy +15..+40 %, Izz +0..+20 %   CAD vs pendulum inertias of
                                                            small quads differ 10-40 %
thrust_mismatch    one motor's thrust and torque             a chipped or bent propeller
 x2                coefficient -5..-15 %                    (5-15 % less thrust)
thrust_factor      every coefficient -5..-15 %               worn propellers, heat
motor_lag x2       yaml tau x 1.5-2.5 (10 -> 15-25 ms;       a slower ESC/motor: time
                   effective 19-46 ms, motor_response)       constants 20-150 ms in the
                                                            literature (motor_lag docs)
rate_damping x2    yaml drag_coef_pqr x 1.5-3                prop guards / a cage add
                                                            frame drag; PyFlyt's own value
                                                            is a "pseudo drag coef"
wind x2            steady wind 1-2.5 m/s, random direction   indoor fans, outdoor calm
                   (PyFlyt's wind field on its body drag)
rotor_delay x2     rotor-speed log 10-30 ms late             ESC telemetry 10-30 ms
                                                            (docs/delays.md)
outside x 4        translational lift +2..+5 % thrust at     RotorPy's k_h model (Folk et
 (x2 each)         1.5 m/s (pybullet force on body z);       al. 2023); a cable or loose
                   a 1-3 Hz roll/pitch torque 1-3 % of       part tugging
                   weight x arm (pybullet torque)
=================  =======================================  ================================

Observability (:func:`oracle_reductions`, :func:`benchmarks.sim_cases.oracle_reductions`):
the references' shared physics that quadsim's nominal model lacks, at its true values
(:func:`shared_effects`): PyFlyt's motor as ``motor_lag`` with its effective time constant,
its body drag as ``body_drag`` (C_d A = drag_coef_xyz x drag_area_xyz; PyFlyt's drag is
per body axis, quadsim's on the speed vector) and its quadratic rate damping as the linear
``rate_damping`` k_i = c E|w_i|^3 / E[w_i^2] (least squares over the references' logged
rates); a case's true difference on top (:func:`library_truth`). A case is observable when
that cuts the flight's normalised residual by at least :data:`OBSERVABLE` (5 %); cases below
it are scored apart and marked, never dropped.

Scoring (:mod:`.score`): in-library -> a reading of the verdict names the truth (a delay:
any reading whose name contains ``delay``); no effect -> ``no_significant_gap``;
out-of-library -> no confident name.
"""

from __future__ import annotations

import numpy as np

from quadsim.effects import make_effect

from . import sim_cases
from .observe import OBSERVABLE
from .pyflyt_source import FlightSpec, motor_response, pyflyt_flights, pyflyt_model, vehicle_params
from .score import joined_kind

__all__ = ["CASES", "OBSERVABLE", "REFERENCES", "SOURCE", "case_list", "case_spec",
           "library_truth", "oracle_reductions", "reference_specs", "shared_effects"]

REFERENCES = 8
DURATION = 8.0
#: (truth, kind, count, speed range)
CASES = (("none", "none", 2, (0.75, 1.35)), ("none", "none", 2, (0.45, 0.55)),
         ("none", "none", 2, (1.5, 1.65)),
         ("mass_offset", "library", 2, None), ("payload", "library", 1, None),
         ("com_offset", "library", 2, None), ("inertia_error", "library", 2, None),
         ("thrust_mismatch", "library", 2, None), ("thrust_factor", "library", 1, None),
         ("motor_lag", "library", 2, None), ("rate_damping", "library", 2, None),
         ("wind", "library", 2, None), ("rotor_delay", "library", 2, None),
         ("translational_lift", "outside", 2, None), ("periodic_torque", "outside", 2, None))
#: library name a case's truth is scored against (payload is an offset mass)
SCORED_AS = {"payload": "mass_offset"}


#: Cases flown as outside the library whose effect the library has gained since the cases
#: were frozen (translational_lift: 4 lift |v_h|^2 along body z,
#: :mod:`quadsim.effects.translational_lift` with k_h = lift). They are scored as in-library;
#: the flights, the case list and so the cache key are unchanged.
JOINED_LIBRARY = frozenset({"translational_lift"})


def scored_kind(case: dict) -> str:
    """The kind a case is scored as today (see :data:`JOINED_LIBRARY`)."""
    return joined_kind(case["case"], case["kind"], JOINED_LIBRARY)


def reference_specs() -> list[FlightSpec]:
    """The 8 nominal reference flights (speeds 0.7-1.4, seeds apart from the cases')."""
    return [FlightSpec(seed=90_000 + 31 * k, speed=0.7 + 0.1 * k, duration=DURATION)
            for k in range(REFERENCES)]


def _draw(truth: str, rng: np.random.Generator) -> dict:
    """PyFlyt-side effects of ``truth`` at a random realistic magnitude (module table;
    :func:`benchmarks.sim_cases.draw_effect`, with PyFlyt's own kinds: its rate drag
    scaled, translational lift)."""
    model = pyflyt_model()
    mass = model["mass"]
    arm = float(np.linalg.norm(model["props"][0][:2]))
    weight = mass * 9.81
    scale = sim_cases.DrawScale(mass=mass, gravity=9.81, arm=arm, damping=0.0,
                                payload_kg=(0.002, 0.005), payload_radius=(0.005, 0.015),
                                payload_below=(0.005, 0.01), wind=(1.0, 2.5))
    own = {"rate_damping": lambda r: {"rate_damping": r.uniform(1.5, 3.0)},
           # +2..5 % of the hover thrust at 1.5 m/s
           "translational_lift": lambda r: {"lift": r.uniform(0.02, 0.05) * weight
                                            / (4 * 1.5 ** 2)}}
    return sim_cases.draw_effect(truth, rng, scale, own)


def case_list() -> list[dict]:
    """The frozen cases: truth (scored name), kind, seed, speed and the PyFlyt effects."""
    return sim_cases.draw_cases(CASES, _draw, source="pyflyt", vehicle="pyflyt-cf2x", seed0=80_000,
                                speeds=(0.75, 1.35), scored_as=SCORED_AS)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


def rate_damping_linear(references: list) -> np.ndarray:
    """PyFlyt's quadratic rate damping c w|w| as the linear k w closest in least squares
    over the references' logged body rates: k_i = c E|w_i|^3 / E[w_i^2] (N m s/rad)."""
    c = pyflyt_model()["drag_coef_pqr"]
    rates = np.concatenate([log.body_rate for log in references])
    return c * np.mean(np.abs(rates) ** 3, axis=0) / np.mean(rates ** 2, axis=0)


def shared_effects(damping: np.ndarray, slow: float = 1.0, pqr: float = 1.0) -> list:
    """PyFlyt's nominal physics that quadsim's nominal model lacks, as library effects at
    their true values (module docstring): motor tau x ``slow``, rate damping ``damping``
    (:func:`rate_damping_linear`) x ``pqr``."""
    model = pyflyt_model()
    _, tau = motor_response(model["tau"] * slow, model["noise_ratio"])
    cd_area = model["drag_coef_xyz"] * model["drag_area_xyz"]
    k = np.asarray(damping, dtype=float) * pqr
    return [make_effect("motor_lag", time_constant=tau),
            make_effect("body_drag", cd_area=cd_area, cd_area_vertical=cd_area),
            make_effect("rate_damping", x=k[0], y=k[1], z=k[2])]


def library_truth(case: dict, damping: np.ndarray) -> list:
    """Library effects with the true difference of ``case`` from the references, on top of
    :func:`shared_effects` (the full effect list of the case's true model); [] for cases
    with no library form (none, outside, delay)."""
    e = case["effects"]
    shared = shared_effects(damping, e.get("motor_slow", 1.0), e.get("rate_damping", 1.0))
    if scored_kind(case) != "library" or "rotor_delay" in e:
        return []
    # [] for motor_slow / rate_damping: the shared effects scaled
    return shared + sim_cases.library_difference(e)


def oracle_reductions(logs: list, references: list,
                      cases: list[dict]) -> list[tuple[float, float]]:
    """Per case (reduction, gap ratio): :func:`benchmarks.sim_cases.oracle_reductions`
    with :func:`shared_effects` and :func:`library_truth`."""
    damping = rate_damping_linear(references)
    return sim_cases.oracle_reductions(logs, references, cases, vehicle_params(),
                                       shared_effects(damping),
                                       lambda case: library_truth(case, damping), scored_kind)


SOURCE = sim_cases.CaseSource(
    name="pyflyt", package="PyFlyt", modules=("pyflyt_source.py", "pyflyt_worker.py",
                                              "simlog.py"),
    references=reference_specs, cases=case_list, case_spec=case_spec, fly=pyflyt_flights,
    observe=oracle_reductions, scored_kind=scored_kind, params=vehicle_params,
    observable=OBSERVABLE)
