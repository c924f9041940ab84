"""battery_sag: thrust falling as the battery discharges (from voltage, or from time).

Formula. A brushless motor's no-load speed is proportional to its supply voltage, so at a
fixed command the thrust ~ Omega^2 ~ V^2 (e.g. Podhradsky, Coopmans & Jensen, "Battery
state-of-charge based altitude controller for small, low cost multirotor unmanned aerial
vehicles", J. Intell. Robot. Syst. 2014, who fit thrust vs. battery voltage)::

    scale = (V / full_voltage)^2                        when the engine supplies V (ctx.vbat)
    scale = max(MIN_SCALE, 1 - rate * t)                otherwise (linear loss with time)

and :meth:`BatterySag.voltage` gives the matching voltage ``full_voltage * sqrt(scale)`` for
flight logs. Modelled as a thrust *and* drag-torque scale at the actual rotor speed: the
equivalent, when only commands are known, of a lower speed for the same command.

Example: ``make_effect("battery_sag", rate=0.005, full_voltage=4.2)`` loses 10 % thrust in
20 s (Crazyflie 1S: 4.2 V -> 3.98 V).
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectLoads, EffectParameter

__all__ = ["MIN_SCALE", "BatterySag"]

MIN_SCALE = 0.5


class BatterySag(EffectBase):
    """Thrust scale from battery voltage (if known) or a linear loss with time."""

    name = "battery_sag"
    parameters = (
        EffectParameter("rate", "1/s", 0.0, 0.0, 0.05,
                        "fraction of thrust lost per second of flight"),
        EffectParameter("full_voltage", "V", 4.2, 1.0, 60.0,
                        "voltage of the full battery (1S LiPo: 4.2 V)"),
    )

    def scale_at(self, t: np.ndarray) -> np.ndarray:
        """Thrust scale (B,) at times t (s) from the time model."""
        return np.maximum(MIN_SCALE, 1.0 - self.rate * np.asarray(t, dtype=float))

    def voltage(self, t: np.ndarray) -> np.ndarray:
        """Battery voltage (V) consistent with the time model at times t (s)."""
        return self.full_voltage * np.sqrt(self.scale_at(t))

    def loads(self, ctx):
        batch, rotors = np.shape(ctx.rotor_speed)
        loads = EffectLoads.neutral(batch, rotors)
        vbat = None if ctx.vbat is None else np.asarray(ctx.vbat, dtype=float)
        if vbat is not None and np.all(np.isfinite(vbat)):
            scale = np.square(vbat / self.full_voltage)
        else:
            scale = self.scale_at(ctx.t)
        loads.thrust_scale = np.repeat(scale[:, None], rotors, axis=1)
        return loads
