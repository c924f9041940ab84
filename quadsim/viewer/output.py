"""Writing a recording (atomic ``.rrd``), streaming it to a spawned viewer, and the
no-display note. Part of :mod:`quadsim.viewer` (see its docstring for the manual)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..core.errors import InputError, QuadsimError
from ..core.files import atomic_write_bytes
from ..vehicle.params import VehicleParams
from ..vehicle.state import Trajectory
from .layout import camera_pose, default_blueprint
from .series import (
    APPLICATION_ID,
    engine_color,
    log_pose_and_thrust,
    log_residuals,
    log_scene,
    log_time_series,
    members_of,
)
from .shapes import vehicle_shapes

__all__ = ["check_output_path", "display_available", "recording_bytes", "save_recording",
           "try_save_recording"]


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
    members = members_of(trajectories, batch_index)
    if measured is not None:
        members.append(("measured", measured))
    scale = _arrow_scale(params) if thrust_arrow_scale is None else float(thrust_arrow_scale)
    span = np.concatenate([np.abs(m.position).max(0) for _, m in members])
    extent = max(1.0, float(np.nanmax(span)) * 1.2)
    log_scene(rec, rr, vehicle_shapes(params, assembly), members, extent)
    samples = 0
    for index, (key, trajectory) in enumerate(members):
        color = engine_color(key, index)
        log_pose_and_thrust(rec, rr, params, key, trajectory, color, scale)
        samples += log_time_series(rec, rr, params, key, trajectory, color)
    default_t = measured.t if measured is not None else members[0][1].t
    residual_names = log_residuals(rec, rr, members, measured, residuals, default_t)
    normalised = any(m.meta.get("command") is not None for _, m in members if m.meta)
    rec.send_blueprint(default_blueprint(rrb, params.rotor_count, residual_names, title,
                                  normalised=normalised, tab=tab, camera=camera_pose(members)))
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
    (:func:`quadsim.core.args.check_output`: name ends in ``.rrd``, not a directory, nearest
    existing parent folder writable). Writes nothing, so a CLI can call it before a long
    simulation."""
    from ..core.args import check_output

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
      assembly: a ``quadsim.cad.assembly`` assembly whose part meshes replace the stand-ins.
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
