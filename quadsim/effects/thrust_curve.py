"""thrust_curve: rotor thrust that is not purely quadratic in rotor speed.

Formula (per rotor, speed Omega in rad/s)::

    T(Omega) = b Omega^2 + linear (Omega - centre) + quadratic (Omega - centre)^2 + offset
                                                                   (N, along the rotor axis)

The nominal model keeps only ``b Omega^2`` (momentum theory with a constant thrust
coefficient, e.g. Bouabdallah, "Design and control of quadrotors", EPFL thesis 2007, eq. 2.4).
Bench sweeps show a linear term: thrust-stand fits of the form T = k2 Omega^2 + k1 Omega + k0
(e.g. the 2015 report's force-lift data, and Crazyflie identification by Förster, "System
identification of the Crazyflie 2.0 nano quadrocopter", ETH 2015, table 3.3, which fits a
quadratic with linear and constant terms). The extra terms enter as a thrust offset along
each rotor axis, acting at the hub; the drag torque is left at ``d Omega^2``. They are part
of the propeller's curve (``EffectLoads.curve_offset``): a propeller change that scales the
thrust (``thrust_factor``, ``thrust_mismatch``) scales them with ``b Omega^2``.

Example: ``make_effect("thrust_curve", linear=-2e-4)`` for the 0.84 kg testbed lowers the
thrust at 460 rad/s (hover) by 0.092 N per rotor (about 4.5 % of the hover thrust).
"""

from __future__ import annotations

import numpy as np

from ..vehicle.params import hover_speed
from .base import EffectBase, EffectLoads, EffectParameter
from .facts import EffectFacts, PlausibleRange, Reading, Scale, Spread, Window, Words, plus_minus
from .scales import hover_thrust_per_speed

__all__ = ["CURVE_QUADRATIC_SD", "ThrustCurve", "curve_quadratic_bounds", "curve_quadratic_sd",
           "hover_thrust_per_speed"]


#: prior spread of a thrust curve's curvature about the hover, as a fraction of b (the
#: b Omega^2 that gives the hover thrust there): stand fits T = k2 W^2 + k1 W + k0 read
#: k2 = 1.10-1.26 b at 40-60 % of the top speed (KDE2814 motor, 10 and 14 inch propellers:
#: Du et al., "Computational Multicopter Design", 2016, measured sweeps), and the published
#: curves of l2f's vehicle files with a large linear term (fs.h, flightmare.h, mrs.h) read
#: k2 = 0.40-0.42 b at their vehicles' hover. Half of b covers both.
CURVE_QUADRATIC_SD = 0.5


def curve_quadratic_bounds(params) -> tuple[float, float]:
    """Bounds (N s^2/rad^2) of a thrust curve's curvature about the hover: the whole
    curvature ``b + quadratic`` from -b to 2 b. Below zero: a curve that flattens towards
    full throttle (l2f's arpl.h: k2 = -0.04 of the b at its hover, a motor that saturates)."""
    return -2.0 * params.thrust_factor, params.thrust_factor


def curve_quadratic_sd(params) -> float:
    """Prior spread (N s^2/rad^2) of the curvature a thrust curve adds about the hover
    (``thrust_curve.quadratic``): :data:`CURVE_QUADRATIC_SD` times b."""
    return CURVE_QUADRATIC_SD * params.thrust_factor


def _phrase(parameter, value, ci, params) -> str:
    """The linear term as its share of the thrust at the hover speed."""
    hover = hover_speed(params)
    rel = value * hover / (params.thrust_factor * hover ** 2)
    crel = None if ci is None else ci * hover / (params.thrust_factor * hover ** 2)
    return (f"{plus_minus(rel, crel, 100)} % thrust at the hover speed "
            f"({value:.3g} N s/rad per rotor)")


class ThrustCurve(EffectBase):
    """Linear and constant thrust terms added to ``b Omega^2``."""

    name = "thrust_curve"
    parameters = (
        EffectParameter("linear", "N s/rad", 0.0, -1.0, 1.0,
                        "thrust per rotor speed, added to b Omega^2"),
        # up to 5 N either way: a stand fit's constant term is a fraction of a rotor's
        # thrust, and rotors run from 0.1 N (Crazyflie) to 20 N (multirotor's 5.5 kg frame);
        # Flightmare's curve (l2f flightmare.h) has -1.77 N
        EffectParameter("offset", "N", 0.0, -5.0, 5.0, "constant thrust per rotor"),
        # a slope about a speed: the thrust there is b centre^2 + offset whatever the slope
        # (the gap's reference model shares it about its flights' mean rotor speed, where b
        # alone then fixes the hover thrust: quadsim.gap.calibrate)
        EffectParameter("centre", "rad/s", 0.0, 0.0, 1e5,
                        "rotor speed about which the linear term acts (0: about zero speed)"),
        # a curvature of its own about the centre: the curve's second derivative is then
        # 2 (b + quadratic). Stand fits T = k2 W^2 + k1 W + k0 matched to b at a hover speed
        # give k2 = 1.10-1.26 b (KDE2814 with 10 and 14 inch propellers, Du et al. 2016);
        # a large negative constant term (Flightmare's -1.77 N) gives k2 well below b. The
        # gap's reference model carries it about the references' hover
        # (quadsim.gap.calibrate). Range: far beyond any frame's b; the gap bounds the whole
        # curvature b + quadratic to -b .. 2 b (quadsim.gap.fitting.curve_quadratic_bounds).
        EffectParameter("quadratic", "N s^2/rad^2", 0.0, -1e-3, 1e-3,
                        "thrust per squared rotor speed about the centre, added to b Omega^2"),
    )

    facts = EffectFacts(
        fitted=("linear",),
        readings=(Reading(("linear",)),),
        scales={"linear": Scale(lambda p: 0.05 * p.thrust_factor * p.max_speed,
                                "5 % of b Omega_max: a few % of the thrust at the top speed"),
                "quadratic": Scale(lambda p: 0.1 * p.thrust_factor,
                                   "the shared curvature about the references' hover: 10 % of b")},
        windows={"linear": Window(lambda p: -hover_thrust_per_speed(p), hover_thrust_per_speed,
                                  "a linear term carrying at most the whole hover thrust"),
                 "quadratic": Window(lambda p: curve_quadratic_bounds(p)[0],
                                     lambda p: curve_quadratic_bounds(p)[1],
                                     "the whole curvature b + quadratic from -b to 2 b")},
        ranges={"linear": PlausibleRange(
            -0.2, 0.2, "hover",
            "bench fits T = k2 W^2 + k1 W + k0 (Foerster, ETH 2015, table 3.3): the linear "
            "term reaches ~20 % of the hover thrust")},
        spreads={"linear": Spread(),
                 "quadratic": Spread(curve_quadratic_sd,
                                     "stand fits and published curves: CURVE_QUADRATIC_SD of b")},
        words={"linear": Words("thrust-curve slope", "N s/rad", 1.0, _phrase),
               "quadratic": Words("thrust-curve curvature", "N s^2/rad^2", 1.0)},
    )

    #: (context fields, vehicle attributes) ``loads`` reads (:attr:`EffectBase.loads_reads`)
    loads_reads = (("rotor_speed",), ())

    def loads(self, ctx):
        speed = np.asarray(ctx.rotor_speed, dtype=float)
        batch, rotors = speed.shape
        loads = EffectLoads.neutral(batch, rotors)
        about = speed - self.centre
        loads.curve_offset = (self.linear + self.quadratic * about) * about + self.offset
        return loads
