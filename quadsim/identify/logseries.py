"""The data types of ``identify --logs`` (:mod:`quadsim.identify.from_logs`): one smoothed log,
the user's skeleton, an estimate with its interval, the whole identification; and the
correlation time that widens intervals for autocorrelated residuals. SI units, body frame
x forward / y left / z up."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import InputError

#: two logs whose b differ by more than this (relative) and beyond their 95 % intervals are
#: logs of different vehicles.
MIX_TOLERANCE = 0.05


@dataclass(frozen=True)
class LogSeries:
    """One log, smoothed on a uniform grid (SI). t (N,) s; specific_force, body_rate,
    body_accel (N, 3) body (m/s^2, rad/s, rad/s^2); rotor_speed, command (N, R) (rad/s,
    normalised 0-1) or None; vbat (N,) V or None; velocity (N, 3) body-frame velocity (m/s)
    or None (a log without a pose; the blade flapping needs it); name: the file."""

    name: str
    t: np.ndarray
    specific_force: np.ndarray
    body_rate: np.ndarray
    body_accel: np.ndarray
    rotor_speed: np.ndarray | None
    command: np.ndarray | None
    vbat: np.ndarray | None
    velocity: np.ndarray | None = None


@dataclass(frozen=True)
class Skeleton:
    """What the user measured: mass (kg), com (3,) m, inertia (3,) kg m^2 diagonal or None,
    rotor positions (R, 3) m (body frame, from the frame centre), spins (R,) +1 ccw / -1 cw,
    max_speed (rad/s) or None, path (for messages)."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray | None
    positions: np.ndarray
    spins: np.ndarray
    max_speed: float | None
    path: str


@dataclass(frozen=True)
class Estimate:
    """A value with its 95 % interval, fit quality and the logs it came from."""

    value: float
    ci95: tuple[float, float]
    quality: str
    identified: bool = True
    why: str = ""


@dataclass
class LogIdentification:
    """Everything :func:`identify_from_logs` found; notes and warnings are one line each;
    ``flapping``: blade flapping [roll, pitch] (kg m/rad, :mod:`quadsim.identify.flapping`),
    empty where it was not read (no rotor speeds or no velocity), an entry None where no log
    could show it."""

    thrust: Estimate
    per_log_thrust: list[tuple[str, float, float]]
    inertia: list[Estimate]
    motor_map: dict | None
    curve: str
    command_only: bool
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    flapping: list[Estimate | None] = field(default_factory=list)


def correlation_time(residual: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time (samples) of a residual (N,), for CI widening."""
    x = residual - residual.mean()
    var = float(x @ x)
    tau = 1.0
    if var <= 0:
        return tau
    for lag in range(1, min(max_lag, len(x) - 1)):
        rho = float(x[lag:] @ x[:-lag]) / var
        if rho < 0.05:
            break
        tau += 2 * rho
    return tau


def confidence_interval(value: float, se: float) -> tuple[float, float]:
    """The 95 % interval (value - 1.96 se, value + 1.96 se) of a Gaussian estimate."""
    return (value - 1.96 * se, value + 1.96 * se)


def origin_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """y = beta x through the origin: (beta, se, R^2)."""
    beta = float(x @ y) / float(x @ x)
    u = y - beta * x
    se = math.sqrt(float(u @ u) / max(1, len(x) - 1) * correlation_time(u) / float(x @ x))
    r2 = 1.0 - float(u @ u) / float(np.sum((y - y.mean()) ** 2))
    return beta, se, r2


def refuse_mixed(per_log: list[tuple[str, float, float]], what: str) -> None:
    """Refuse logs of different vehicles: two per-log values (name, value, se) more than
    :data:`MIX_TOLERANCE` apart *and* beyond their combined 95 % interval."""
    for (na, ba, sa), (nb, bb, sb) in itertools.combinations(per_log, 2):
        gap = abs(ba - bb)
        if gap > MIX_TOLERANCE * max(abs(ba), abs(bb)) and gap > 1.96 * math.hypot(sa, sb):
            raise InputError(
                f"{nb}: {what}: {bb:.4g} here but {ba:.4g} in {na} "
                f"({100 * gap / max(abs(ba), abs(bb)):.1f} % apart, beyond both 95 % intervals "
                f"and the {100 * MIX_TOLERANCE:.0f} % tolerance): logs of different vehicles "
                "(or payloads) mixed; identify each vehicle on its own logs")
