"""l2f benchmark cases: each a single flight judged per flight against 8 nominal flights.

Source: :mod:`.l2f_source` (l2f 2.0.18, RLtools' "Learning to Fly" simulator: its own
single-precision RK4 rigid body, first-order rotor model and identified Holybro X500, 2.0
kg; this project adds only a body drag, the effects l2f has no parameter for, and a PID
cascade: l2f ships none). The cases are *frozen*: drawn once from fixed seeds
(:func:`case_list`), cached by ``benchmarks/gap_benchmark.py --independent --source l2f
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

from functools import partial

import numpy as np

from quadsim.effects import make_effect
from quadsim.effects.thrust_factor import ThrustFactor
from quadsim.gap.fitting import momentum_rate_damping

from . import sim_cases
from .l2f_source import (
    ARPL,
    FLIGHTMARE,
    FS,
    MODEL,
    MRS,
    SOFT,
    FlightSpec,
    hover_command,
    l2f_flights,
    stand_b,
    vehicle_params,
)
from .observe import OBSERVABLE
from .score import joined_kind

__all__ = ["CASES", "OBSERVABLE", "REFERENCES", "SOURCE", "VehicleCases", "case_list",
           "case_spec", "library_truth", "oracle_reductions", "reference_specs",
           "shared_effects"]

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


class VehicleCases:
    """The frozen cases of one l2f vehicle (:data:`benchmarks.l2f_source.VEHICLES`):
    ``key`` its name there, ``vehicle`` its table, ``arm`` (m), the payload's ranges (kg,
    m, m) and the seeds of its cases and references."""

    def __init__(self, key: str, vehicle: dict, arm: float, payload_kg, payload_radius,
                 payload_below, seed0: int, ref_seed0: int):
        self.key, self.vehicle, self.arm = key, vehicle, arm
        self.payload = (payload_kg, payload_radius, payload_below)
        self.seed0, self.ref_seed0 = seed0, ref_seed0

    def params(self):
        return vehicle_params(self.vehicle)

    def reference_specs(self) -> list[FlightSpec]:
        """The 8 nominal reference flights (speeds 0.7-1.4, seeds apart from the cases')."""
        return [FlightSpec(seed=self.ref_seed0 + 37 * k, speed=0.7 + 0.1 * k,
                           duration=DURATION) for k in range(REFERENCES)]

    def draw(self, truth: str, rng: np.random.Generator) -> dict:
        """l2f-side effects of ``truth`` at a random realistic magnitude (module table;
        :func:`benchmarks.sim_cases.draw_effect`)."""
        m = self.vehicle
        kg, radius, below = self.payload
        scale = sim_cases.DrawScale(
            mass=m["mass"], gravity=m["gravity"], arm=self.arm,
            damping=momentum_rate_damping(self.params()), payload_kg=kg,
            payload_radius=radius, payload_below=below,
            hover_state=hover_command(vehicle=m))
        return sim_cases.draw_effect(truth, rng, scale)

    def case_list(self) -> list[dict]:
        """The frozen cases: truth (scored name), kind, seed, speed and the l2f effects."""
        return sim_cases.draw_cases(CASES, self.draw, source="l2f",
                                    vehicle=self.vehicle["name"], seed0=self.seed0,
                                    speeds=(0.75, 1.35), scored_as=SCORED_AS)

    def shared_effects(self, slow: float = 1.0) -> list:
        """l2f's nominal physics that quadsim's nominal model lacks, as library effects at
        their true values (module docstring): the rotor time constant (x ``slow``), the
        body drag, and where l2f's thrust is not purely quadratic its curve against the
        stand fit's b (:func:`benchmarks.l2f_source.stand_b`): a propeller factor
        c2 / (b omega_max^2) - 1 with no speed-per-command change and the curve's linear and
        constant terms (its reaction torque k_Q (c0 + c1 a) has no library form)."""
        m = self.vehicle
        cd = m["cd_area"]
        out = [make_effect("motor_lag", time_constant=m["tau"] * slow),
               make_effect("body_drag", cd_area=cd[0], cd_area_vertical=cd[2])]
        if self.curve_factor() == 1.0 and (m["c0"] != 0.0 or m["c1"] != 0.0):
            # no propeller factor (curve_factor): the curve's curvature against b instead
            b = stand_b(m)
            return out + [make_effect("thrust_curve", linear=m["c1"] / m["omega_max"],
                                      offset=m["c0"],
                                      quadratic=m["c2"] / m["omega_max"] ** 2 - b)]
        if m["c0"] != 0.0 or m["c1"] != 0.0:
            factor = self.curve_factor()
            # built directly: the mrs vehicle's factor (0.45) lies beyond make_effect's
            # plausible range for a reading (a stand fit over a = 0.1..1 of a curve whose
            # linear term carries most of its thrust)
            out += [ThrustFactor(change=factor - 1, alpha=0.0),
                    make_effect("thrust_curve", linear=m["c1"] / m["omega_max"] / factor,
                                offset=m["c0"] / factor)]
        return out

    def curve_factor(self) -> float:
        """c2 / (b omega_max^2): the propeller factor of :meth:`shared_effects`, 1 for a
        purely quadratic rotor. A propeller factor scales the whole curve
        (``EffectLoads.curve_offset``), so the curve's terms are stated divided by it."""
        m = self.vehicle
        if m["c0"] == 0.0 and m["c1"] == 0.0:
            return 1.0
        factor = m["c2"] / (stand_b(m) * m["omega_max"] ** 2)
        # a curve whose c2 is no propeller's: one that bends down (arpl, c2 < 0), or one
        # whose linear term carries nearly all of it (soft_rigid: 0.068). A factor scales the
        # drag torque as well, and l2f's is k_Q times the whole thrust: below a quarter the
        # truth's yaw torque would be off by more than 4x. Its c2 is then a curvature against
        # b (thrust_curve.quadratic), the drag torque left at d Omega^2 (1.3x low at hover)
        return 1.0 if factor < MIN_CURVE_FACTOR else factor

    def library_truth(self, case: dict) -> list:
        """Library effects with the true difference of ``case`` from the references, on top
        of :meth:`shared_effects` (the full effect list of the case's true model); [] for
        cases with no library form (none, outside, delay)."""
        e = case["effects"]
        shared = self.shared_effects(e.get("motor_slow", 1.0))
        if scored_kind(case) != "library" or "rotor_delay" in e:
            return []
        # [] for motor_slow: the shared rotor lag scaled; alpha 0 (module doc)
        return shared + sim_cases.library_difference(
            e, linear_per_speed=1.0 / (self.vehicle["omega_max"] * self.curve_factor()),
            rate_damping=True)

    def oracle_reductions(self, logs: list, references: list,
                          cases: list[dict]) -> list[tuple[float, float]]:
        """Per case (reduction, gap ratio): :func:`benchmarks.sim_cases.oracle_reductions`
        with :meth:`shared_effects` and :meth:`library_truth`."""
        return sim_cases.oracle_reductions(logs, references, cases, self.params(),
                                           self.shared_effects(), self.library_truth,
                                           scored_kind)

    def source(self, name: str) -> sim_cases.CaseSource:
        return sim_cases.CaseSource(
            name=name, package="l2f",
            modules=("l2f_source.py", "flightjobs.py", "simlog.py"),
            references=self.reference_specs, cases=self.case_list, case_spec=case_spec,
            fly=partial(l2f_flights, vehicle=self.key), observe=self.oracle_reductions,
            scored_kind=scored_kind, params=self.params, observable=OBSERVABLE)


def case_spec(case: dict) -> FlightSpec:
    return FlightSpec(seed=case["seed"], speed=case["speed"], duration=DURATION,
                      effects=dict(case["effects"]))


#: the smallest propeller factor c2 / (b omega_max^2) a curved rotor's truth is stated with
#: (:meth:`VehicleCases.curve_factor`); below it the curve's c2 is stated as a curvature
MIN_CURVE_FACTOR = 0.25


#: the X500 (module table); seeds as frozen when the source was built
X500 = VehicleCases("x500", MODEL, ARM, (0.1, 0.3), (0.02, 0.05), (0.02, 0.06),
                    seed0=80_000, ref_seed0=90_000)
#: the fs vehicle (:mod:`.l2f_fs_cases`): arm 0.319 m, a payload 0.15-0.5 kg 30-80 mm off
#: the centre and 30-80 mm below (a 3.35 kg vehicle's gimbal or sensor), its own seeds
FS_CASES = VehicleCases("fs", FS, float(np.hypot(0.20895, 0.240666)), (0.15, 0.5),
                        (0.03, 0.08), (0.03, 0.08), seed0=81_000, ref_seed0=91_000)
#: the flightmare vehicle (:mod:`.l2f_flightmare_cases`): arm 0.17 m, a payload 0.04-0.11
#: kg (the X500's share of its mass) 15-40 mm off the centre and 15-45 mm below, its own seeds
FLIGHTMARE_CASES = VehicleCases("flightmare", FLIGHTMARE, 0.17, (0.04, 0.11), (0.015, 0.04),
                                (0.015, 0.045), seed0=82_000, ref_seed0=92_000)
#: the mrs vehicle (:mod:`.l2f_mrs_cases`): arm 0.17 m, a payload 0.085-0.255 kg (the X500's
#: share of its mass) 20-50 mm off the centre and 20-60 mm below, its own seeds
MRS_CASES = VehicleCases("mrs", MRS, 0.17, (0.085, 0.255), (0.02, 0.05), (0.02, 0.06),
                         seed0=84_000, ref_seed0=94_000)
#: the arpl vehicle (:mod:`.l2f_arpl_cases`): arm 0.0775 m (the rectangle's shorter
#: half-span, the pitch lever: with its 0.125 m diagonal a 9.2 mm CoM offset was lost at 8 s,
#: before any verdict), a payload 0.04-0.12 kg (the X500's share of its mass) 15-40 mm off
#: the centre and 15-45 mm below, its own seeds
ARPL_CASES = VehicleCases("arpl", ARPL, 0.0775, (0.04, 0.12),
                          (0.015, 0.04), (0.015, 0.045), seed0=85_000, ref_seed0=95_000)
#: the soft_rigid vehicle (:mod:`.l2f_soft_cases`): arm 0.142 m (the rectangle's shorter
#: half-span, as arpl's), a payload 0.04-0.12 kg 15-40 mm off the centre and 15-45 mm below,
#: its own seeds
SOFT_CASES = VehicleCases("soft", SOFT, 0.142, (0.04, 0.12), (0.015, 0.04), (0.015, 0.045),
                          seed0=86_000, ref_seed0=96_000)

reference_specs = X500.reference_specs
case_list = X500.case_list
shared_effects = X500.shared_effects
library_truth = X500.library_truth
oracle_reductions = X500.oracle_reductions
SOURCE = X500.source("l2f")
