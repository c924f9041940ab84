"""MJCF generation: one free body with explicit inertial, rotor sites and rotor actuators.

The body's ``<inertial>`` is written explicitly (``fullinertia`` about the CoM) from the
parameter set, so MuJoCo never recomputes it from geoms; visual geoms carry no mass.

Rotor actuators
---------------
One ``<general>`` actuator per rotor, transmitted through the rotor's hub site whose z axis is
the rotor's thrust axis. **The control is the squared rotor speed Omega^2 in rad^2/s^2.**
With gain 1 and ``gear = [0, 0, b, 0, 0, -spin * d]`` the actuator produces thrust
``b * Omega^2`` along the axis and the reaction torque ``-spin * d * Omega^2`` about it
(spin = +1 ccw), exactly :func:`quadsim.vehicle.rotors.allocation_matrix`. ``ctrlrange`` is
``[min_speed^2, max_speed^2]``. Use :func:`speed_to_ctrl` to convert.

MuJoCo's built-in fluid drag is off (``density = 0``, ``viscosity = 0``) so that drag is
modelled only by the effect plug-ins and never counted twice.
"""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..vehicle.params import VehicleParams, hover_speed

BODY_NAME = "vehicle"


def speed_to_ctrl(rotor_speed: np.ndarray) -> np.ndarray:
    """Rotor speed (rad/s) -> actuator control (rad^2/s^2)."""
    return np.square(np.asarray(rotor_speed, dtype=float))


def _vec(values) -> str:
    """Numbers for the MJCF: 15 significant digits, and components below 1e-12 of the
    vector's largest set to 0, so that floating-point noise of the mesh libraries (which
    differs between their versions) does not change the bytes of the model."""
    flat = np.ravel(np.asarray(values, dtype=float))
    scale = float(np.max(np.abs(flat))) if flat.size else 0.0
    flat = np.where(np.abs(flat) < 1e-12 * scale, 0.0, flat)
    return " ".join(f"{float(v):.15g}" for v in flat)


def rotor_site_name(index: int) -> str:
    return f"rotor{index + 1}"


def vehicle_xml(params: VehicleParams, *, timestep: float = 1e-3, integrator: str = "RK4",
                visual_geoms: str = "", assets: str = "", floor: bool = True,
                comment: str = "") -> str:
    """MJCF text for the vehicle described by ``params``.

    ``visual_geoms``/``assets`` are inserted verbatim (mesh geoms built from the CAD folder
    by :mod:`quadsim.build_mjcf`); without them simple geoms stand in for the frame and
    rotors. The vehicle starts 1 m above the floor; keyframe ``hover`` holds it there."""
    inertia = params.inertia
    full = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2],
            inertia[1, 2]]
    arm = float(np.max(np.linalg.norm(params.rotor_positions[:, :2], axis=1)))
    radius = params.rotor_radius or 0.25 * arm
    sites, actuators, stand_ins = [], [], []
    for i, rotor in enumerate(params.rotors):
        name = rotor_site_name(i)
        sites.append(
            f'      <site name="{name}" pos="{_vec(rotor.position)}" zaxis="{_vec(rotor.axis)}"'
            f' size="{radius:.6g} 0.002" type="cylinder" group="1" rgba="0.2 0.6 1 0.3"/>'
        )
        gear = [0, 0, params.thrust_factor, 0, 0, -rotor.spin * params.drag_factor]
        actuators.append(
            f'    <general name="{name}" site="{name}" gear="{_vec(gear)}" ctrllimited="true"'
            f' ctrlrange="{params.min_speed**2:.17g} {params.max_speed**2:.17g}"/>'
            f"  <!-- rotor {rotor.name}, {'ccw' if rotor.spin > 0 else 'cw'};"
            " ctrl = Omega^2 (rad^2/s^2) -->"
        )
        stand_ins.append(
            f'      <geom class="collision" type="capsule" fromto="0 0 0 {_vec(rotor.position)}"'
            ' size="0.008"/>'
        )
    hover_ctrl = _vec([hover_speed(params) ** 2] * params.rotor_count)
    floor_xml = ('    <geom name="floor" type="plane" size="0 0 0.1" rgba="0.8 0.8 0.8 1"'
                 ' contype="1" conaffinity="1"/>\n') if floor else ""
    note = f"<!-- {comment} -->\n" if comment else ""
    inertia_note = f"mass properties from parameter set {params.name!s}: " \
        f"{params.sources.get('inertia', '')}"
    return f"""{note}<mujoco model={quoteattr(params.name)}>
  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>
  <option timestep="{timestep:.17g}" integrator="{integrator}" gravity="0 0 {-params.gravity:.17g}"
          density="0" viscosity="0"/>
  <default>
    <default class="visual">
      <geom contype="0" conaffinity="0" group="2" mass="0" density="0"/>
    </default>
    <default class="collision">
      <geom contype="1" conaffinity="1" group="3" mass="0" density="0" rgba="0.5 0.5 0.5 0.4"/>
    </default>
  </default>
  <asset>
{assets}  </asset>
  <worldbody>
{floor_xml}    <body name="{BODY_NAME}" pos="0 0 1">
      <freejoint name="{BODY_NAME}"/>
      <!-- {inertia_note} -->
      <inertial pos="{_vec(params.com)}" mass="{params.mass:.15g}" fullinertia="{_vec(full)}"/>
{visual_geoms or chr(10).join(stand_ins)}
{chr(10).join(sites)}
    </body>
  </worldbody>
  <actuator>
{chr(10).join(actuators)}
  </actuator>
  <keyframe>
    <key name="hover" qpos="0 0 1 1 0 0 0" ctrl="{hover_ctrl}"/>
  </keyframe>
</mujoco>
"""
