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
recording could not be written: catch :class:`~quadsim.errors.QuadsimError` around
:func:`save_recording`, or call :func:`try_save_recording`, which prints the one-line error to
stderr and returns None.

Output is deterministic in content (``rerun rrd compare a.rrd b.rrd`` succeeds for two runs
with the same inputs); the bytes differ between runs because rerun stamps chunk and row ids
with the wall clock.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError, QuadsimError
from .fileio import atomic_write_bytes
from .params import VehicleParams
from .trajectory import STATE12_NAMES, STATE12_UNITS, Trajectory

__all__ = [
    "APPLICATION_ID",
    "TIMELINE",
    "ENGINE_COLORS",
    "VehicleShape",
    "engine_color",
    "vehicle_shapes",
    "assembly_for",
    "rotor_thrust",
    "state_residuals",
    "recording_bytes",
    "save_recording",
    "check_output_path",
    "try_save_recording",
    "display_available",
]

APPLICATION_ID = "quadsim"
TIMELINE = "time"
SAMPLE_TIMELINE = "sample"
#: Colours (RGB) of the line strips, arrows and plot lines per engine.
ENGINE_COLORS = {
    "mujoco": (31, 119, 180),
    "analytic": (255, 127, 14),
    "measured": (20, 20, 20),
}
_EXTRA_COLORS = ((44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
                 (227, 119, 194), (23, 190, 207))
_ANGLE_STATES = ("roll", "pitch", "yaw")


@dataclass(frozen=True)
class VehicleShape:
    """One triangle mesh of the vehicle: vertices (V, 3) in m, body frame; faces (F, 3)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[int, int, int]


def engine_color(key: str, index: int = 0) -> tuple[int, int, int]:
    """Colour for an engine key such as ``mujoco``, ``analytic_2`` or ``measured``."""
    base = key.rsplit("_", 1)[0] if key.rsplit("_", 1)[-1].isdigit() else key
    if base in ENGINE_COLORS:
        return ENGINE_COLORS[base]
    return _EXTRA_COLORS[index % len(_EXTRA_COLORS)]


# ----------------------------------------------------------------------------- pure helpers


def rotor_thrust(params: VehicleParams, rotor_speed: np.ndarray) -> np.ndarray:
    """Thrust magnitude per rotor (..., R) in N: ``b * Omega^2`` for speeds (..., R) rad/s."""
    return params.thrust_factor * np.square(np.asarray(rotor_speed, dtype=float))


def _resample(t_from: np.ndarray, values: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    """Linear interpolation of (N, K) ``values`` onto ``t_to``; NaN outside ``t_from``."""
    if len(t_from) == len(t_to) and np.allclose(t_from, t_to, rtol=0, atol=1e-12):
        return values
    out = np.full((len(t_to), values.shape[1]), np.nan)
    inside = (t_to >= t_from[0]) & (t_to <= t_from[-1])
    for k in range(values.shape[1]):
        out[inside, k] = np.interp(t_to[inside], t_from, values[:, k])
    return out


def state_residuals(model: Trajectory, measured: Trajectory) -> np.ndarray:
    """Model minus measured, (N_measured, 12), on the measured time stamps.

    ``model`` (one member, not a batch) is interpolated linearly onto ``measured.t``; rows
    outside the model's time span are NaN. Euler-angle residuals are wrapped to [-pi, pi)
    so a yaw crossing +-pi does not show as a 2 pi error."""
    model_states = model.state12()
    # Unwrap before interpolating so a yaw crossing +-pi is not averaged through zero.
    model_states[:, 6:9] = np.unwrap(model_states[:, 6:9], axis=0)
    residual = _resample(np.asarray(model.t, float), model_states, np.asarray(measured.t, float))
    residual = residual - measured.state12()
    residual[:, 6:9] = (residual[:, 6:9] + np.pi) % (2 * np.pi) - np.pi
    return residual


def _box(size: Sequence[float], center: Sequence[float], direction: np.ndarray | None = None):
    import trimesh  # local: only needed when a recording is made

    mesh = trimesh.creation.box(extents=size)
    if direction is not None:
        mesh.apply_transform(trimesh.geometry.align_vectors([1.0, 0.0, 0.0], direction))
    mesh.apply_translation(center)
    return mesh


def _simple_shapes(params: VehicleParams) -> list[VehicleShape]:
    """Stand-in geometry from the rotor layout: a centre plate, an arm to every hub and a
    thin disc of the rotor radius at each hub, oriented along the rotor axis."""
    import trimesh

    positions = params.rotor_positions
    arm = float(np.max(np.linalg.norm(positions[:, :2], axis=1))) or 0.1
    radius = params.rotor_radius or 0.3 * arm
    shapes = [VehicleShape("plate", *_mesh_arrays(_box([0.5 * arm, 0.5 * arm, 0.04 * arm],
                                                       params.com)), (90, 90, 90))]
    for i, (position, axis, spin) in enumerate(zip(positions, params.rotor_axes,
                                                   params.rotor_spins)):
        length = float(np.linalg.norm(position)) or 1e-3
        arm_mesh = _box([length, 0.06 * arm, 0.04 * arm], 0.5 * position, position / length)
        shapes.append(VehicleShape(f"arm_{i + 1}", *_mesh_arrays(arm_mesh), (120, 120, 120)))
        disc = trimesh.creation.cylinder(radius=radius, height=0.01 * arm, sections=32)
        disc.apply_transform(trimesh.geometry.align_vectors([0.0, 0.0, 1.0], axis))
        disc.apply_translation(position + 0.03 * arm * axis)
        color = (60, 160, 230) if spin > 0 else (230, 120, 50)  # ccw blue, cw orange
        shapes.append(VehicleShape(f"rotor_{i + 1}", *_mesh_arrays(disc), color))
    return shapes


def _mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32)


_GROUP_COLORS = {"mechanical": (150, 150, 160), "battery": (200, 170, 40),
                 "avionics": (40, 140, 80)}


def _assembly_shapes(assembly) -> list[VehicleShape]:
    """Every placed instance of every CAD part, in the body frame (m); propellers coloured by
    spin (ccw blue, cw orange) when they sit on a rotor hub."""
    spins = {tuple(np.round(r.position, 6)): r.spin for r in assembly.rotors}
    shapes = []
    for part in assembly.parts:
        vertices = np.asarray(part.mesh.vertices, dtype=float)
        faces = np.asarray(part.mesh.faces, dtype=np.uint32)
        for placement in part.placements:
            body = vertices @ np.asarray(placement.rotation).T + placement.position
            color = _GROUP_COLORS.get(part.group, (150, 150, 160))
            spin = spins.get(tuple(np.round(placement.position, 6)))
            if "prop" in part.name and spin is not None:
                color = (60, 160, 230) if spin > 0 else (230, 120, 50)
            shapes.append(VehicleShape(f"{part.name}/{placement.name}",
                                       body.astype(np.float32), faces, color))
    return shapes


def assembly_for(params: VehicleParams):
    """The CAD assembly the parameter set's mass properties or rotor layout come from
    (``from_cad``), or None when the set does not come from CAD."""
    if params.cad_dir is None:
        return None
    from .assembly import load_assembly  # local: trimesh and the mesh files

    return load_assembly(params.cad_dir)


def vehicle_shapes(params: VehicleParams, assembly=None) -> list[VehicleShape]:
    """Meshes to draw for the vehicle: the assembly's parts when given, else stand-ins."""
    if assembly is not None:
        return _assembly_shapes(assembly)
    return _simple_shapes(params)


# ----------------------------------------------------------------------------- logging


def _members(trajectories: Mapping[str, Trajectory], batch_index) -> list[tuple[str, Trajectory]]:
    """(key, single-flight trajectory) pairs; batches reduced to the chosen members."""
    chosen = []
    for key, trajectory in trajectories.items():
        key = _entity_part(key)
        if not isinstance(trajectory, Trajectory):
            raise InputError(f"trajectories[{key!r}]: expected a quadsim Trajectory, "
                             f"got {type(trajectory).__name__}")
        if trajectory.position.ndim == 2:
            chosen.append((key, trajectory))
            continue
        size = trajectory.position.shape[0]
        indices = range(size) if batch_index == "all" else np.atleast_1d(batch_index).tolist()
        for i in indices:
            if not 0 <= i < size:
                raise InputError(f"trajectories[{key!r}]: batch_index {i} outside 0..{size - 1}")
            name = key if len(indices) == 1 else f"{key}_{i}"
            chosen.append((name, trajectory.select(i)))
    return chosen


def _time(rr, t: np.ndarray):
    return [rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=float))]


def _log_scalars(rec, rr, path: str, t: np.ndarray, values: np.ndarray, key: str,
                 color) -> int:
    """One plot line; returns the number of samples sent (NaN samples are dropped)."""
    values = np.asarray(values, dtype=float)
    keep = np.isfinite(values)
    if not np.any(keep):
        return 0
    rec.log(path, rr.SeriesLines(colors=[color], names=[key], widths=[1.5]), static=True)
    rec.send_columns(path, indexes=_time(rr, t[keep]),
                     columns=rr.Scalars.columns(scalars=values[keep]))
    return int(np.count_nonzero(keep))


def _log_scene(rec, rr, shapes: list[VehicleShape], members, extent: float) -> None:
    """Static parts: world axes, ground plane, vehicle meshes under each engine's pose."""
    rec.log("world/axes", rr.TransformAxes3D(axis_length=0.5 * extent), static=True)
    half = extent
    corners = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]],
                       dtype=np.float32)
    rec.log("world/ground", rr.Mesh3D(vertex_positions=corners,
                                      triangle_indices=[[0, 1, 2], [0, 2, 3]],
                                      albedo_factor=[200, 200, 200, 110]), static=True)
    for key, _ in members:
        for shape in shapes:
            albedo = [*shape.color, 255 if key.startswith("mujoco") else 140]
            rec.log(f"world/{key}/vehicle/body/{shape.name}",
                    rr.Mesh3D(vertex_positions=shape.vertices, triangle_indices=shape.faces,
                              albedo_factor=albedo), static=True)


def _log_pose_and_thrust(rec, rr, params, key, trajectory, color, arrow_scale) -> None:
    t = np.asarray(trajectory.t, dtype=float)
    w, x, y, z = np.moveaxis(np.asarray(trajectory.quat, dtype=float), -1, 0)
    # The sample index rides along as a second timeline: rerun 0.41's viewer did not load
    # Transform3D columns sent on a single timeline (checked headless, docs/viewer.md).
    indexes = _time(rr, t) + [rr.TimeColumn(SAMPLE_TIMELINE, sequence=np.arange(len(t)))]
    rec.send_columns(
        f"world/{key}/vehicle", indexes=indexes,
        columns=rr.Transform3D.columns(translation=trajectory.position,
                                       quaternion=np.stack([x, y, z, w], -1)))
    rec.log(f"world/{key}/path",
            rr.LineStrips3D([np.asarray(trajectory.position, np.float32)], colors=[color],
                            radii=[0.004], labels=[key]), static=True)
    rotor_count = trajectory.rotor_speed.shape[-1]
    if rotor_count != params.rotor_count:
        return  # a log without rotor speeds: pose and path only
    thrust = rotor_thrust(params, trajectory.rotor_speed)  # (N, R) N
    vectors = (thrust * arrow_scale)[..., None] * params.rotor_axes  # body frame, m
    # Hubs and colours never change: static, so only the vectors are sent per sample.
    rec.log(f"world/{key}/vehicle/thrust",
            rr.Arrows3D.from_fields(origins=params.rotor_positions, colors=[color] * rotor_count,
                                    radii=[0.004] * rotor_count), static=True)
    columns = rr.Arrows3D.columns(vectors=vectors.reshape(-1, 3))
    rec.send_columns(f"world/{key}/vehicle/thrust", indexes=_time(rr, t),
                     columns=columns.partition([rotor_count] * len(t)))


def _log_time_series(rec, rr, params, key, trajectory, color) -> int:
    t = np.asarray(trajectory.t, dtype=float)
    sent = 0
    states = trajectory.state12()
    for k, name in enumerate(STATE12_NAMES):
        sent += _log_scalars(rec, rr, f"states/{name}/{key}", t, states[:, k], key, color)
    speeds = trajectory.rotor_speed
    if speeds.shape[-1] == params.rotor_count:
        thrust = rotor_thrust(params, speeds)
        for i in range(speeds.shape[-1]):
            sent += _log_scalars(rec, rr, f"rotors/speed_{i + 1}/{key}", t, speeds[:, i], key,
                                 color)
            sent += _log_scalars(rec, rr, f"rotors/thrust_{i + 1}/{key}", t, thrust[:, i], key,
                                 color)
    if trajectory.rotor_command is not None:
        for i in range(trajectory.rotor_command.shape[-1]):
            sent += _log_scalars(rec, rr, f"rotors/command_{i + 1}/{key}", t,
                                 trajectory.rotor_command[:, i], key, color)
    normalised = trajectory.meta.get("command") if trajectory.meta else None
    if normalised is not None:
        for i in range(np.shape(normalised)[-1]):
            sent += _log_scalars(rec, rr, f"rotors/command_norm_{i + 1}/{key}", t,
                                 np.asarray(normalised)[:, i], key, color)
    return sent


def _residual_table(residuals: Mapping, default_t: np.ndarray):
    """Normalise caller residuals to ``[(path, t, values (N,))]``.

    Each value is an (N,) or (N, K) array on ``default_t`` (the measured time stamps, or the
    first trajectory's), or a pair ``(t, values)``, or a triple ``(t, values, labels)``."""
    table = []
    for name, value in residuals.items():
        labels = None
        if isinstance(value, tuple) and len(value) in (2, 3):
            t, values = np.asarray(value[0], float), np.asarray(value[1], float)
            labels = value[2] if len(value) == 3 else None
        else:
            t, values = default_t, np.asarray(value, dtype=float)
        values = values.reshape(len(values), -1) if values.ndim != 1 else values[:, None]
        if len(values) != len(t):
            raise InputError(f"residuals[{name!r}]: {len(values)} samples, time has {len(t)}")
        labels = list(labels) if labels is not None else (
            [str(k) for k in range(values.shape[1])] if values.shape[1] > 1 else [None])
        if len(labels) != values.shape[1]:
            raise InputError(f"residuals[{name!r}]: {len(labels)} labels for "
                             f"{values.shape[1]} columns")
        for k, label in enumerate(labels):
            path = f"residuals/{_entity_part(name)}" + (
                f"/{_entity_part(label)}" if label is not None else "")
            table.append((path, t, values[:, k], str(label if label is not None else name)))
    return table


def _entity_part(text: object) -> str:
    """A label made safe as one entity-path part (``Fx (N)`` -> ``Fx_N``); the readable
    label stays in the plot legend."""
    part = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(text)).strip("_")
    return part or "_"


def _log_residuals(rec, rr, members, measured, residuals, default_t) -> list[str]:
    """Model-minus-measured states per engine and the caller's residuals; returns the
    residual view names."""
    names: list[str] = []
    if measured is not None:
        for index, (key, trajectory) in enumerate(members):
            if key == "measured":
                continue
            table = state_residuals(trajectory, measured)
            for k, name in enumerate(STATE12_NAMES):
                _log_scalars(rec, rr, f"residuals/{name}/{key}", measured.t, table[:, k], key,
                             engine_color(key, index))
        names += list(STATE12_NAMES)
    for index, (path, t, values, label) in enumerate(_residual_table(residuals or {},
                                                                      default_t)):
        _log_scalars(rec, rr, path, t, values, label, _EXTRA_COLORS[index % len(_EXTRA_COLORS)])
        group = path.split("/")[1]
        if group not in names:
            names.append(group)
    return names


def _plot(rrb, origin: str, name: str, first: bool):
    """A time-series view; only the first of a grid shows its legend (colours repeat)."""
    legend = rrb.PlotLegend(corner="RightBottom", visible=first)
    return rrb.TimeSeriesView(origin=origin, name=name, plot_legend=legend)


def _rotor_views(rrb, rotor_count: int, normalised: bool) -> list:
    views = []
    for i in range(1, rotor_count + 1):
        views += [_plot(rrb, f"rotors/speed_{i}", f"rotor {i} speed (rad/s)", i == 1),
                  _plot(rrb, f"rotors/command_{i}", f"rotor {i} command (rad/s)", i == 1),
                  _plot(rrb, f"rotors/thrust_{i}", f"rotor {i} thrust b Omega^2 (N)", i == 1)]
        if normalised:
            views.append(_plot(rrb, f"rotors/command_norm_{i}", f"rotor {i} command (0-1)",
                               i == 1))
    return views


def _blueprint(rrb, rotor_count: int, residual_names: list[str], title: str, *,
               normalised: bool = False, tab: str = "states", camera=None):
    """3D view on the left; tabs of plot grids (states, rotors, residuals) on the right.

    ``camera``: (eye position, look target) in the world frame (m), or None for rerun's."""
    units = dict(zip(STATE12_NAMES, STATE12_UNITS))
    state_views = [_plot(rrb, f"states/{n}", f"{n} ({units[n]})", k == 0)
                   for k, n in enumerate(STATE12_NAMES)]
    tabs = [rrb.Grid(*state_views, grid_columns=3, name="states"),
            rrb.Grid(*_rotor_views(rrb, rotor_count, normalised),
                     grid_columns=4 if normalised else 3, name="rotors")]
    if residual_names:
        residual_views = [_plot(rrb, f"residuals/{n}", f"{n} model - measured ({units[n]})"
                                if n in units else n, k == 0)
                          for k, n in enumerate(residual_names)]
        tabs.append(rrb.Grid(*residual_views, grid_columns=3, name="residuals"))
    names = [t.name for t in tabs]
    if tab not in names:
        raise InputError(f"plot tab {tab!r} not in this recording; valid: {', '.join(names)}")
    eye = None
    if camera is not None:
        eye = rrb.EyeControls3D(position=camera[0], look_target=camera[1], eye_up=[0, 0, 1])
    scene = rrb.Spatial3DView(origin="world", name=title or "vehicle", eye_controls=eye,
                              line_grid=rrb.LineGrid3D(visible=True, spacing=0.25))
    return rrb.Blueprint(rrb.Horizontal(scene, rrb.Tabs(*tabs, active_tab=names.index(tab)),
                                        column_shares=[2, 3]),
                         rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
                         collapse_panels=True)


def _camera(members) -> tuple[np.ndarray, np.ndarray]:
    """Eye and target that frame every path: look at the paths' centre from the front-left,
    above, at a distance that grows with the paths' extent."""
    points = np.concatenate([np.asarray(m.position, float) for _, m in members])
    points = points[np.all(np.isfinite(points), axis=1)]
    low, high = points.min(0), points.max(0)
    target = 0.5 * (low + high)
    distance = max(1.5, 1.8 * float(np.linalg.norm(high - low)))
    return target + distance * np.array([-0.55, -0.75, 0.45]), target


def _arrow_scale(params: VehicleParams) -> float:
    """Metres per newton: a hover thrust arrow is half an arm long."""
    arm = float(np.max(np.linalg.norm(params.rotor_positions[:, :2], axis=1))) or 0.1
    return 0.5 * arm / (params.weight / params.rotor_count)


def _check_inputs(params, trajectories, measured) -> None:
    if not trajectories and measured is None:
        raise InputError("save_recording: nothing to log (no trajectories and no measured flight)")
    for key, trajectory in {**trajectories, "measured": measured}.items():
        if trajectory is None:
            continue
        rotors = trajectory.rotor_speed.shape[-1]
        if rotors not in (0, params.rotor_count):
            raise InputError(f"trajectories[{key!r}]: {rotors} rotor speeds, model "
                             f"{params.name!r} has {params.rotor_count} rotors")
    if measured is not None and measured.position.ndim != 2:
        raise InputError("measured: expected one flight, got a batch")


def _record(rec, params, trajectories, measured, residuals, assembly, title, batch_index,
            thrust_arrow_scale, tab="states") -> dict:
    """Send everything to ``rec``; returns counts for the caller (entities, samples)."""
    import rerun as rr
    import rerun.blueprint as rrb

    _check_inputs(params, trajectories, measured)
    members = _members(trajectories, batch_index)
    if measured is not None:
        members.append(("measured", measured))
    scale = _arrow_scale(params) if thrust_arrow_scale is None else float(thrust_arrow_scale)
    span = np.concatenate([np.abs(m.position).max(0) for _, m in members])
    extent = max(1.0, float(np.nanmax(span)) * 1.2)
    _log_scene(rec, rr, vehicle_shapes(params, assembly), members, extent)
    samples = 0
    for index, (key, trajectory) in enumerate(members):
        color = engine_color(key, index)
        _log_pose_and_thrust(rec, rr, params, key, trajectory, color, scale)
        samples += _log_time_series(rec, rr, params, key, trajectory, color)
    default_t = measured.t if measured is not None else members[0][1].t
    residual_names = _log_residuals(rec, rr, members, measured, residuals, default_t)
    normalised = any(m.meta.get("command") is not None for _, m in members if m.meta)
    rec.send_blueprint(_blueprint(rrb, params.rotor_count, residual_names, title,
                                  normalised=normalised, tab=tab, camera=_camera(members)))
    return {"members": [key for key, _ in members], "scalar_samples": samples}


def recording_bytes(*, params: VehicleParams, trajectories: Mapping[str, Trajectory],
                    measured: Trajectory | None = None, residuals: Mapping | None = None,
                    assembly=None, title: str = "", batch_index: int | Sequence[int] | str = 0,
                    thrust_arrow_scale: float | None = None, tab: str = "states",
                    recording_id: str = "quadsim") -> bytes:
    """The ``.rrd`` bytes of a recording (see :func:`save_recording` for the arguments)."""
    import rerun as rr

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id, send_properties=False)
    memory = rec.memory_recording()
    try:
        _record(rec, params, trajectories, measured, residuals, assembly, title, batch_index,
                thrust_arrow_scale, tab)
        if title:
            rec.send_recording_name(title)
        rec.flush()
        return memory.drain_as_bytes()
    finally:
        rec.disconnect()


def display_available() -> bool:
    """Whether a native viewer window can open here (a display on Linux; always elsewhere)."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _no_display_note(path: Path | None) -> None:
    where = (f"view the recording with `rerun {path}` where a display exists, or headless with "
             f"`rerun --web-viewer {path}`" if path is not None else
             "save the recording to a file (e.g. --rerun out.rrd) and view it with `rerun FILE`"
             " or `rerun --web-viewer FILE`")
    print(f"note: no display here (DISPLAY/WAYLAND_DISPLAY unset), no viewer opened; {where} "
          "(see docs/viewer.md)", file=sys.stderr)


def _spawn_viewer(path: Path) -> None:
    """Open ``path`` in the native rerun viewer, or say how to view it without a display."""
    if not display_available():
        _no_display_note(path)
        return
    try:
        subprocess.Popen([sys.executable, "-m", "rerun", str(path)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    except OSError as exc:
        raise InputError(f"{path}: cannot start the rerun viewer: {exc}") from None


def check_output_path(path: str | os.PathLike) -> Path:
    """Raise :class:`InputError` (one line) unless a recording can be written at ``path``
    (:func:`quadsim.cliargs.check_output`: name ends in ``.rrd``, not a directory, nearest
    existing parent folder writable). Writes nothing, so a CLI can call it before a long
    simulation."""
    from .cliargs import check_output

    check_output("recording", path, (".rrd",))
    return Path(path)


def save_recording(path: str | os.PathLike | None, *, params: VehicleParams,
                   trajectories: Mapping[str, Trajectory], measured: Trajectory | None = None,
                   spawn: bool = False, residuals: Mapping | None = None, assembly=None,
                   title: str = "", batch_index: int | Sequence[int] | str = 0,
                   thrust_arrow_scale: float | None = None, tab: str = "states"
                   ) -> Path | None:
    """Write a rerun recording of simulated (and measured) flights to ``path`` (``.rrd``).

    Args:
      path: output file, written atomically; None with ``spawn=True`` only opens a viewer.
      params: the vehicle (rotor geometry, b for thrust arrows, stand-in meshes).
      trajectories: engine name -> :class:`Trajectory` (e.g. ``{"mujoco": .., "analytic": ..}``).
      measured: a measured flight (``FlightLog.to_trajectory()``); adds residual plots.
      spawn: also open the native viewer where a display exists (else print how to view).
      residuals: extra residual series, name -> (N,) / (N, K) array on the measured (or first
        trajectory's) time stamps, or ``(t, values[, labels])``.
      assembly: a ``quadsim.assembly`` assembly whose part meshes replace the stand-ins.
      title: recording name and 3D view title.
      batch_index: member(s) of batched trajectories to log: an int, a list, or ``"all"``.
      thrust_arrow_scale: arrow length per newton (m/N); default: hover thrust = half an arm.
      tab: plot tab shown first: ``states``, ``rotors`` or (with residuals) ``residuals``.

    Returns the path written (None when only spawned). Raises :class:`InputError` (one line)
    for an unusable path or inconsistent inputs; nothing is written then.
    """
    options = dict(params=params, trajectories=dict(trajectories), measured=measured,
                   residuals=residuals, assembly=assembly, title=title, batch_index=batch_index,
                   thrust_arrow_scale=thrust_arrow_scale, tab=tab)
    if path is None:
        if not spawn:
            raise InputError("save_recording: give an output path or spawn=True")
        return _spawn_stream(options)
    path = check_output_path(path)
    atomic_write_bytes(path, recording_bytes(**options))
    if spawn:
        _spawn_viewer(path)
    return path


def _spawn_stream(options: dict) -> None:
    """Stream straight to a newly spawned native viewer (no file)."""
    import rerun as rr
    import rerun.blueprint  # noqa: F401  (loaded before the viewer connects)

    if not display_available():
        _no_display_note(None)
        return None
    rec = rr.RecordingStream(APPLICATION_ID, send_properties=False)
    rec.spawn()
    try:
        _record(rec, options["params"], options["trajectories"], options["measured"],
                options["residuals"], options["assembly"], options["title"],
                options["batch_index"], options["thrust_arrow_scale"], options["tab"])
        rec.flush()
    finally:
        rec.disconnect()
    return None


def try_save_recording(path: str | os.PathLike | None, **kwargs) -> Path | None:
    """:func:`save_recording`, but a :class:`QuadsimError` becomes one line on stderr
    (``error: ...``) and None, so that the caller keeps (and saves) its simulation result."""
    try:
        return save_recording(path, **kwargs)
    except QuadsimError as exc:
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return None
