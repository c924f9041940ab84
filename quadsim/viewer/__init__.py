"""Rerun recordings of simulated and measured flights: 3D vehicle, thrust arrows, paths, plots.

:func:`save_recording` writes one ``.rrd`` file that opens readable in the rerun viewer
(``rerun out.rrd``, or the web viewer, see ``docs/viewer.md``)::

    >>> from quadsim.viewer import save_recording
    >>> save_recording("out/flight.rrd", params=params,
    ...                trajectories={"mujoco": traj_m, "analytic": traj_a},
    ...                measured=log.to_trajectory())

What is logged (entity paths; ``<key>`` is the engine name, ``measured`` for the log):

* ``world/axes`` world axes, ``world/ground`` a ground plane at z = 0 (static).
* ``world/<key>/vehicle`` the vehicle pose over time (``Transform3D`` columns, body to world);
  below it ``.../body/<part>`` the vehicle's meshes (CAD parts of the assembly when given, or
  simple shapes built from the rotor geometry) and ``.../thrust`` one arrow per rotor along its
  axis with length ``thrust_arrow_scale * b * Omega_i^2`` (m per N), drawn in the body frame
  so that rerun places it in the world with the pose.
* ``world/<key>/path`` the whole path as one line strip, one colour per engine.
* ``states/<state>/<key>`` every state of the 12-state convention (x, y, z, vx, vy, vz, roll,
  pitch, yaw, p, q, r; SI units, angles in rad).
* ``rotors/speed_<i>/<key>``, ``rotors/command_<i>/<key>`` (rad/s), ``rotors/thrust_<i>/<key>``
  (N); a log's normalised commands under ``rotors/command_norm_<i>/measured`` (0-1).
* ``residuals/<state>/<key>`` model minus measured for each engine when ``measured`` is given
  (model interpolated linearly onto the measured time stamps inside the model's time span;
  angle residuals wrapped to [-pi, pi)); extra caller residuals under ``residuals/<name>/...``.
* a default blueprint: the 3D view on the left, tabs of plots (states, rotors, residuals) on
  the right.

Time is the ``time`` timeline (a duration in seconds). Everything is sent with
``send_columns`` (one call per entity, no per-sample loops) on a dedicated
``RecordingStream`` held in memory, then written atomically (temporary file in the same
folder, ``os.replace``). Batched trajectories: only the members named by ``batch_index``
(default: member 0) are logged, each as ``<key>_<i>`` when more than one is chosen.

Rerun is imported lazily, inside the functions, so importing an engine that may log costs
nothing when logging is off. Callers that simulate should not lose their result because a
recording could not be written: catch :class:`~quadsim.core.errors.QuadsimError` around
:func:`save_recording`, or call :func:`try_save_recording`, which prints the one-line error to
stderr and returns None.

Output is deterministic in content (``rerun rrd compare a.rrd b.rrd`` succeeds for two runs
with the same inputs); the bytes differ between runs because rerun stamps chunk and row ids
with the wall clock.
"""

from __future__ import annotations

from .output import (
                     check_output_path,
                     display_available,
                     recording_bytes,
                     save_recording,
                     try_save_recording,
)
from .series import (
                     APPLICATION_ID,
                     ENGINE_COLORS,
                     TIMELINE,
                     engine_color,
                     rotor_thrust,
                     state_residuals,
)
from .shapes import VehicleShape, assembly_for, vehicle_shapes

__all__ = [
                     "APPLICATION_ID",
                     "ENGINE_COLORS",
                     "TIMELINE",
                     "VehicleShape",
                     "assembly_for",
                     "check_output_path",
                     "display_available",
                     "engine_color",
                     "recording_bytes",
                     "rotor_thrust",
                     "save_recording",
                     "state_residuals",
                     "try_save_recording",
                     "vehicle_shapes",
]
