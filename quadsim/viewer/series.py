"""Sending flights to a rerun recording: poses, paths, thrust arrows, state / rotor / residual
time series (one ``send_columns`` call per entity). Part of :mod:`quadsim.viewer`; the
entity paths are listed in its docstring."""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np

from ..core.errors import InputError
from ..vehicle.params import VehicleParams
from ..vehicle.state import STATE12_NAMES, Trajectory
from .shapes import VehicleShape

__all__ = ["APPLICATION_ID", "ENGINE_COLORS", "TIMELINE", "engine_color", "rotor_thrust",
           "state_residuals"]

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



# ----------------------------------------------------------------------------- logging


def members_of(trajectories: Mapping[str, Trajectory], batch_index) -> list[tuple[str, Trajectory]]:
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


def log_scene(rec, rr, shapes: list[VehicleShape], members, extent: float) -> None:
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


def log_pose_and_thrust(rec, rr, params, key, trajectory, color, arrow_scale) -> None:
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


def log_time_series(rec, rr, params, key, trajectory, color) -> int:
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


def log_residuals(rec, rr, members, measured, residuals, default_t) -> list[str]:
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

