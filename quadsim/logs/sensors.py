"""Sensor models for logged signals: delay, sample rate, bias, noise, quantisation; seeded.

A :class:`SensorModel` turns a true :class:`~quadsim.logs.flightlog.FlightLog` (what the
simulator knows) into what sensors would have recorded. Steps, in this order:

1. **delay** (s, all signals): the value logged at t is the truth at ``t - delay`` (linear
   interpolation; the first sample is held before the log starts);
2. **rate** (Hz): samples at ``k / rate`` from the (delayed) truth by linear interpolation
   (quaternions: normalised linear interpolation); ``None`` keeps the simulation's samples;
3. **bias** (per signal, same value on every axis): a constant offset; for ``attitude`` a
   constant rotation of ``bias`` rad about each body axis;
4. **noise** (per signal, standard deviation): white Gaussian, drawn from
   ``numpy.random.default_rng(seed)`` in the fixed order of :data:`SIGNALS`; for
   ``attitude`` a small random rotation (rad) applied in the body frame;
5. **quantisation** (per signal, step): values rounded to the nearest multiple of the step.

Signals and units (the flight-log columns they act on):

=============  ========  ==================
signal         unit      columns
=============  ========  ==================
``position``   m         x, y, z
``velocity``   m/s       vx, vy, vz
``attitude``   rad       qw..qz (rotation)
``gyro``       rad/s     wx, wy, wz
``accel``      m/s^2     ax, ay, az
``rotor``      rad/s     rotor_1..rotor_N
``vbat``       V         vbat
=============  ========  ==================

Commands (``cmd_i``) are logged exactly. Example::

    >>> from quadsim.logs.sensors import SensorModel
    >>> sensors = SensorModel(noise={"position": 1e-3, "gyro": 0.01}, rate=200.0, delay=0.005)
    >>> measured = sensors.apply(true_log, seed=0)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import InputError
from ..core.frames import quat_multiply, quat_normalize
from .flightlog import FlightLog

__all__ = ["SIGNALS", "SensorModel", "parse_signal_values", "rotation_quat"]

#: signal -> (unit, FlightLog attribute)
SIGNALS = {
    "position": ("m", "position"),
    "velocity": ("m/s", "velocity"),
    "attitude": ("rad", "quat"),
    "gyro": ("rad/s", "body_rate"),
    "accel": ("m/s^2", "accel"),
    "rotor": ("rad/s", "rotor_speed"),
    "vbat": ("V", "vbat"),
}


def rotation_quat(rotation_vector: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) of rotation vectors (..., 3) (rad), exact exponential map."""
    rotation_vector = np.asarray(rotation_vector, dtype=float)
    angle = np.linalg.norm(rotation_vector, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(x/2)/x -> 1/2 as x -> 0
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate([np.cos(half), scale * rotation_vector], axis=-1)


def parse_signal_values(text: str, *, flag: str, signed: bool = False) -> dict[str, float]:
    """``"position=0.001,gyro=0.01"`` -> dict; names must be in :data:`SIGNALS`; values
    finite and >= 0 (any sign with ``signed``, for biases)."""
    values: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, eq, number = item.partition("=")
        name = name.strip()
        if not eq:
            raise InputError(f"{flag}: {item!r} is not signal=value")
        if name not in SIGNALS:
            raise InputError(f"{flag}: unknown signal {name!r}; valid: {', '.join(SIGNALS)}")
        try:
            value = float(number)
        except ValueError:
            raise InputError(f"{flag}: {name}: {number.strip()!r} is not a number") from None
        if not (np.isfinite(value) and (signed or value >= 0.0)):
            raise InputError(f"{flag}: {name}: must be finite{'' if signed else ' and >= 0'}, "
                             f"got {value:g}")
        values[name] = value
    return values


def _interpolate(t_new: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t_new, t, column) for column in np.atleast_2d(values.T)],
                    axis=-1).reshape(len(t_new), *values.shape[1:])


@dataclass(frozen=True)
class SensorModel:
    """Noise/bias/quantisation per signal (see :data:`SIGNALS`), one delay and sample rate."""

    noise: dict[str, float] = field(default_factory=dict)
    bias: dict[str, float] = field(default_factory=dict)
    quantization: dict[str, float] = field(default_factory=dict)
    rate: float | None = None
    delay: float = 0.0

    def __post_init__(self):
        for label in ("noise", "bias", "quantization"):
            unknown = set(getattr(self, label)) - set(SIGNALS)
            if unknown:
                raise InputError(f"sensor {label}: unknown signal(s) {sorted(unknown)}; "
                                 f"valid: {', '.join(SIGNALS)}")
        if self.quantization.get("attitude", 0.0):
            raise InputError("sensor quantization: attitude (quaternions) cannot be quantised")
        if self.rate is not None and not (np.isfinite(self.rate) and self.rate > 0):
            raise InputError(f"sensor rate: must be positive (Hz), got {self.rate}")
        if not (np.isfinite(self.delay) and self.delay >= 0):
            raise InputError(f"sensor delay: must be >= 0 (s), got {self.delay}")

    def to_json(self) -> dict:
        """Plain description (units included) for truth sidecars."""
        units = {name: unit for name, (unit, _) in SIGNALS.items()}
        return {"noise_std": dict(sorted(self.noise.items())),
                "bias": dict(sorted(self.bias.items())),
                "quantization_step": dict(sorted(self.quantization.items())),
                "rate_hz": self.rate, "delay_s": self.delay, "units": units}

    def _resample(self, log: FlightLog) -> FlightLog:
        t = log.t
        if self.rate is None:
            t_new = t
        else:
            t_new = t[0] + np.arange(0.0, t[-1] - t[0] + 1e-12, 1.0 / self.rate)
        source = np.maximum(t_new - self.delay, t[0])
        if self.rate is None and self.delay == 0.0:
            return log
        changes = {"t": t_new}
        for name in ("position", "velocity", "quat", "body_rate", "accel", "rotor_speed",
                     "rotor_command", "vbat"):
            value = getattr(log, name)
            if value is not None:
                changes[name] = _interpolate(source, t, value)
        changes["quat"] = quat_normalize(changes["quat"])
        return dataclasses.replace(log, **changes)

    def apply(self, log: FlightLog, *, seed: int) -> FlightLog:
        """The log as the sensors would record it (a new FlightLog; ``log`` is unchanged)."""
        log = self._resample(log)
        rng = np.random.default_rng(seed)
        changes = {}
        for signal, (_, attribute) in SIGNALS.items():
            value = getattr(log, attribute)
            if value is None:
                continue
            value = np.array(value, dtype=float)
            bias, noise = self.bias.get(signal, 0.0), self.noise.get(signal, 0.0)
            if signal == "attitude":
                rotation = np.full(value.shape[:-1] + (3,), bias)
                if noise > 0:
                    rotation = rotation + rng.normal(0.0, noise, rotation.shape)
                if bias or noise:
                    value = quat_normalize(quat_multiply(value, rotation_quat(rotation)))
            else:
                value = value + bias
                if noise > 0:
                    value = value + rng.normal(0.0, noise, value.shape)
                step = self.quantization.get(signal, 0.0)
                if step > 0:
                    value = np.round(value / step) * step
            changes[attribute] = value
        return dataclasses.replace(log, **changes)
