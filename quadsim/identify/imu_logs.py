"""``identify --logs`` on logs without rotor speeds: load, cut to every airborne stretch,
identify from the IMU and the commands (:mod:`.imu`), and hand the result to the set writer.

The I/O glue of :func:`quadsim.identify.imu.identify_imu` (which is pure math). Logs of any
format :func:`quadsim.logs.flightlog.load_log` reads; each log's ground and idle spans are cut
and *every* airborne stretch is used (:func:`quadsim.logs.checks.check_log_stretches`).

Example::

    >>> ident, notes = identify_from_imu_logs(["log10", "log15"], skeleton)
"""

from __future__ import annotations

import warnings
from pathlib import Path

from ..core.errors import InputError, QuadsimWarning

__all__ = ["MAX_STEP_S", "identify_from_imu_logs", "load_checked", "log_names", "wants_imu_path"]


#: the IMU + commands identification needs a log at this step (s) or finer: T_m is tens of
#: ms and its balances use windows of :data:`quadsim.identify.imu.WINDOW_S` = 20 ms; a
#: coarser log (an ArduCopter log's 10 Hz attitude rows) keeps the commands-only thrust map.
MAX_STEP_S = 0.01


def wants_imu_path(logs) -> bool:
    """Whether ``logs`` (FlightLogs) are for the IMU + commands identification: no rotor
    speeds in any, or no pose in one (the rotor-speed fits need the pose's states);
    commands, accelerometer and gyro in every one, at ``MAX_STEP_S`` or finer."""
    import numpy as np

    if not logs or (any(log.rotor_speed is not None for log in logs)
                    and all(log.has_pose for log in logs)):
        return False
    return all(log.rotor_command is not None and log.accel is not None
               and log.body_rate is not None and len(log.t) > 2
               and float(np.median(np.diff(log.t))) <= MAX_STEP_S for log in logs)


def load_checked(paths) -> tuple[list, list[str]]:
    """(FlightLogs, one per file, notes): every file read and validated (warnings become
    notes); nothing cut yet."""
    from ..logs.flightlog import load_log

    logs, notes = [], []
    for path in paths:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", QuadsimWarning)
            logs.append(load_log(path))
        notes += [str(w.message) for w in caught]
    return logs, notes


def identify_from_imu_logs(logs, skeleton, notes: list[str] | None = None):
    """(LogIdentification for :func:`quadsim.identify.vehicle_set.build_set`, notes) from
    FlightLogs with IMU and commands: every airborne stretch of every log, T_m, the thrust
    map, Ixx and Iyy with their intervals (:mod:`.imu`). Raises :class:`InputError` (file and
    field) when a log lacks what the fit needs or the skeleton's rotor count differs."""
    import numpy as np

    from ..logs.checks import check_log_stretches
    from ..logs.flightlog import WITHOUT_POSE, WITHOUT_POSITION
    from .imu import identification_for_set, identify_imu, segments_from_logs

    notes = list(notes or [])
    stretches = []
    for log in logs:
        if log.rotor_command is not None and log.rotor_command.shape[1] != len(
                skeleton.positions):
            raise InputError(f"{log.path}: cmd_*: {log.rotor_command.shape[1]} motor commands "
                             f"in the log, {len(skeleton.positions)} rotors in {skeleton.path}: "
                             "a log of another vehicle, or the wrong skeleton?")
        parts, found = check_log_stretches(log)
        stretches += parts
        notes += [n for n in found if n not in notes and WITHOUT_POSE not in n
                  and WITHOUT_POSITION not in n]
    for words in (WITHOUT_POSE, WITHOUT_POSITION):
        bare = [Path(str(log.path)).name for log in logs if log.without_pose_words == words]
        if bare:
            notes.append(f"{', '.join(bare)}: {words}")
    arms = np.asarray(skeleton.positions, float) - np.asarray(skeleton.com, float)
    ident = identify_imu(segments_from_logs(stretches), mass=skeleton.mass, arms=arms)
    return identification_for_set(ident, skeleton, stretches=len(stretches)), notes


def log_names(paths) -> str:
    """The logs' file names, comma separated (for the written set's sources)."""
    return ", ".join(Path(p).name for p in paths)
