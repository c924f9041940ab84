"""battery_sag: a discharging battery gives less rotor speed for the same command.

Physics. A brushless motor's no-load speed is proportional to its supply voltage (speed
constant K_v, rad/s per V), so at a fixed command (duty cycle) the steady rotor speed scales
with the voltage, and the thrust ~ Omega^2 ~ V^2 (e.g. Podhradsky, Coopmans & Jensen,
"Battery state-of-charge based altitude controller for small, low cost multirotor unmanned
aerial vehicles", J. Intell. Robot. Syst. 2014, who fit thrust vs. battery voltage)::

    speed factor  f = V / full_voltage                   when the voltage is known (vbat)
    speed factor  f = sqrt(max(MIN_SCALE, 1 - rate t))   otherwise (thrust falls by rate per s)
    steady speed  Omega_ss = f * Omega_command

The battery acts *upstream* of the rotor speed (hook :meth:`speed_factor`, see
:mod:`quadsim.effects.base`): at a measured rotor speed the thrust is unchanged. With
measured rotor speeds it is therefore seen only on the command -> speed channel; a loss of
thrust *per Omega^2* is a propeller/air effect (:mod:`quadsim.effects.thrust_factor`).
In the engines, without a motor-lag effect, the rotor follows ``f * Omega_command`` with the
fast response :data:`quadsim.effects.base.SPEED_RESPONSE_S`.

:meth:`BatterySag.voltage` gives the matching voltage ``full_voltage * sqrt(scale)`` for
flight logs.

:func:`nominal_voltage` is the full voltage a vehicle's battery has when no effect says
otherwise (what a generated log records for a nominal flight).

Example: ``make_effect("battery_sag", rate=0.005, full_voltage=4.2)`` loses 10 % thrust (5 %
speed) at a fixed command in 20 s (Crazyflie 1S: 4.2 V -> 3.98 V).
"""

from __future__ import annotations

import numpy as np

from .base import EffectBase, EffectParameter
from .facts import EffectFacts, PlausibleRange, Scale, Spread, Words, plus_minus

__all__ = ["CELL_VOLTAGE", "MIN_SCALE", "VBAT_SD", "VOLTAGE_TESTED", "BatterySag",
           "nominal_voltage", "voltage_spread"]

MIN_SCALE = 0.5

#: a charged LiPo cell (V)
CELL_VOLTAGE = 4.2
#: prior spread of a full battery voltage (fraction of the pack's voltage): its charge
#: state, +-10 % (the ``full_voltage`` spread of :attr:`BatterySag.facts`)
VBAT_SD = 0.1
#: vehicles lighter than this (kg) fly on one cell
ONE_CELL_BELOW_KG = 0.1
#: a law in the logged voltage (speed or thrust per command ~ vbat) is tested only where the
#: logs' voltage varies by at least this fraction of its mean (:func:`voltage_spread`); below
#: it the law's slope is not determined (a steady voltage: one column of the fit constant).
#: 1 %: a hover speed 1 % off, several times a rotor-speed channel's noise. Read by the
#: diagnosis' references (``quadsim.gap.calibrate.VBAT_TESTED``) and by the identification
#: from IMU and commands (:mod:`quadsim.identify.imu`).
VOLTAGE_TESTED = 0.01


def voltage_spread(series) -> tuple[float, float]:
    """(mean, relative spread) of logged battery voltages ``series`` (an iterable of (N,)
    arrays, V): the spread (max - min) of the mean voltage over each quarter of each series,
    so that the voltage log's sample noise averages out, over their mean; (nan, 0) where no
    sample is given."""
    means = [float(np.mean(q)) for v in series
             for q in np.array_split(np.asarray(v, float), 4) if len(q)]
    if not means:
        return float("nan"), 0.0
    mean = float(np.mean(means))
    return mean, float((max(means) - min(means)) / mean) if mean > 0 else 0.0


def nominal_voltage(params) -> float:
    """Full battery voltage (V) of a vehicle: one LiPo cell below 100 g (Crazyflie 2.1: a 1S
    250 mAh pack, Bitcraze), three above (the 0.84 kg testbed's Turnigy D2830-11 1000 kV
    motors are sized for 3S; the report does not name its pack, so this is an assumption)."""
    return CELL_VOLTAGE * (1 if params.mass < ONE_CELL_BELOW_KG else 3)


def _phrase(parameter, value, ci, params) -> str:
    """A battery's reading: the voltage law's full voltage, or a sag rate."""
    if parameter == "full_voltage":
        return (f"the rotors turn slower per command as the battery drops: speed = nominal "
                f"map x vbat / ({plus_minus(value, ci, 1.0, '.3g')} V), i.e. 1 % slower per "
                f"{10 * value:.3g} mV below {value:.3g} V (thrust at a fixed command: 2 % "
                "lower per 1 % of voltage)")
    per_minute = plus_minus(100 * 60 * value / 2, None if ci is None else 100 * 60 * ci / 2,
                            1.0)
    return (f"the rotors lose {per_minute} "
            f"% speed per minute at a fixed command ({100 * 60 * value:.2g} % thrust per "
            "minute; a discharging battery)")


class BatterySag(EffectBase):
    """Rotor speed per command from battery voltage (if known) or a linear loss with time."""

    name = "battery_sag"
    parameters = (
        EffectParameter("rate", "1/s", 0.0, 0.0, 0.05,
                        "fraction of thrust (at a fixed command) lost per second of flight"),
        EffectParameter("full_voltage", "V", 4.2, 1.0, 60.0,
                        "voltage of the full battery (1S LiPo: 4.2 V)"),
    )

    facts = EffectFacts(
        fitted=("rate",),
        with_voltage_log=("full_voltage",),
        upstream_of_speed=True,
        # with a voltage log the sag (V / V_full)^2 acts for every V_full
        no_off_value=("full_voltage",),
        starts_at_logged_voltage=("full_voltage",),
        scales={"rate": Scale(lambda p: 0.005, "0.5 %/s: a failing cell"),
                "full_voltage": Scale(lambda p: 0.2, "0.2 V: a cell's charge state")},
        ranges={"rate": PlausibleRange(0.0, 0.005, "absolute",
                                       "1S LiPo: ~20 % thrust over a 5-7 min flight")},
        spreads={"rate": Spread(),
                 "full_voltage": Spread(lambda p: VBAT_SD * nominal_voltage(p),
                                        "a battery's full voltage: +-10 % (charge state) of "
                                        "the vehicle's pack")},
        words={"rate": Words("speed lost per minute at a fixed command", "%/min", 3000.0, _phrase),
               "full_voltage": Words("full battery voltage", "V", 1.0, _phrase)},
    )

    def scale_at(self, t: np.ndarray) -> np.ndarray:
        """Thrust scale at a fixed command (B,) at times t (s) from the time model."""
        return np.maximum(MIN_SCALE, 1.0 - self.rate * np.asarray(t, dtype=float))

    def voltage(self, t: np.ndarray) -> np.ndarray:
        """Battery voltage (V) consistent with the time model at times t (s)."""
        return self.full_voltage * np.sqrt(self.scale_at(t))

    def speed_factor(self, t, vbat=None):
        """Steady rotor speed per nominal speed of a command (B,); None when off."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if vbat is not None:
            v = np.asarray(vbat, dtype=float)
            if v.shape == t.shape and np.all(np.isfinite(v)):
                return v / self.full_voltage  # a voltage log: the sag follows it
        if self.rate == 0.0:
            return None
        return np.sqrt(self.scale_at(t))
