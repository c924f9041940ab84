"""body_drag: parasitic (form) drag of the airframe, quadratic in air velocity.

Formula (v the vehicle's air velocity, i.e. velocity minus wind, in body axes; rho the air
density of the parameter set)::

    F_body = -0.5 rho |v| diag(cd_area, cd_area, cd_area_vertical) v       (N, at the CoM)

the standard drag equation (e.g. Hoerner, "Fluid-dynamic drag", 1965, ch. 1; used for
multirotors in Mahony, Kumar & Corke, "Multirotor aerial vehicles", IEEE RAM 2012, sec. "Drag").
``cd_area`` is the product C_d A (m^2) seen from the front/side, ``cd_area_vertical`` from
above. Example: C_d A = 0.01 m^2 at 5 m/s, rho = 1.225: 0.153 N.

With ``per_axis = 1`` each body axis's drag follows its own air speed, a box's faces taken
apart (PyFlyt's drag, ``F_i = -1/2 rho C_dA_i |v_i| v_i``)::

    F_body,i = -0.5 rho C_dA_i |v_i| v_i

The two laws agree for air along one body axis; along a diagonal of the horizontal plane the
per-axis law's force is 1/sqrt(2) of the other's at the same C_d A.

MuJoCo's own fluid model is switched off in every generated model (``<option density="0"
viscosity="0">`` in :mod:`quadsim.sim.mjcf`), so this plug-in is the only body drag and it acts
identically in both engines; nothing is counted twice.
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectLoads, EffectParameter
from .facts import ALL, EffectFacts, Reading, Scale, Spread, Words, plus_minus

__all__ = ["BodyDrag", "area_scale"]


def area_scale(params) -> float:
    """A C_d A (m^2) giving 10 % of the weight at 2 m/s: ``0.1 m g / (rho / 2 (2 m/s)^2)``."""
    return 0.1 * params.weight / (0.5 * params.air_density * 4.0)


def _phrase(parameter, value, ci, params) -> str:
    """C_d A in cm² and its force at 2 m/s."""
    where = "sideways" if parameter == "cd_area" else "vertical"
    force = 0.5 * params.air_density * value * 4.0
    return (f"body drag {where} C_d A {plus_minus(value, ci, 1e4)} cm² ({1e3 * force:.2g} mN, "
            f"{100 * force / (params.mass * params.gravity):.2g} % of the weight, at 2 m/s)")


class BodyDrag(EffectBase):
    """Quadratic airframe drag with separate horizontal and vertical C_d A."""

    name = "body_drag"
    parameters = (
        EffectParameter("cd_area", "m^2", 0.0, 0.0, 1.0,
                        "drag coefficient x area, body x and y directions"),
        EffectParameter("cd_area_vertical", "m^2", 0.0, 0.0, 1.0,
                        "drag coefficient x area, body z direction"),
        EffectParameter("per_axis", "1", 0.0, 0.0, 1.0,
                        "1: each body axis's drag on its own air speed |v_i| v_i; 0: on "
                        "the air speed |v| v"),
    )

    facts = EffectFacts(
        needs_pose=("velocity", "attitude"),   # drag of the air velocity in the body frame
        fitted=("cd_area", "cd_area_vertical"),
        readings=(Reading(("cd_area", "cd_area_vertical")),),
        scales={p: Scale(area_scale, "a C_d A giving 10 % of the weight at 2 m/s")
                for p in ("cd_area", "cd_area_vertical")},
        spreads={ALL: Spread(area_scale, "10 % of the weight at 2 m/s: a doubled drag")},
        words={"cd_area": Words("body drag sideways C_d A", "cm^2", 1e4, _phrase),
               "cd_area_vertical": Words("body drag vertical C_d A", "cm^2", 1e4, _phrase),
               "per_axis": Words("drag law per body axis", "1", 1.0)},
    )

    #: (context fields, vehicle attributes) ``loads`` reads (:attr:`EffectBase.loads_reads`)
    loads_reads = (("air_velocity",), ("air_density",))

    def loads(self, ctx):
        air_body = ctx.to_body(ctx.air_velocity)
        cd_area = np.array([self.cd_area, self.cd_area, self.cd_area_vertical])
        speed = (np.abs(air_body) if self.per_axis >= 0.5
                 else np.linalg.norm(air_body, axis=-1, keepdims=True))
        force_body = -0.5 * ctx.params.air_density * speed * cd_area * air_body
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        loads.force_world = ctx.to_world(force_body)
        return loads
