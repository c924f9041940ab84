"""Layout of one simulation's effect parameters in the compiled path (a row of ``encode``'s array).

Shared by the driver (:mod:`quadsim.sim.compiled`, which fills the rows) and the numba kernel
(:mod:`quadsim.sim.compiled.kernel`, which reads them); no numba needed to import it.
``OFFSET[name]`` is the first column of parameter ``name``; ``WIDTH`` the row length.
"""

from __future__ import annotations

__all__ = ["GUST", "MAX_ROTORS", "OFFSET", "WIDTH"]

GUST = 8            # gust components of quadsim.effects.wind
MAX_ROTORS = 8
# Layout of one simulation's effect parameters (a row of ``encode``'s array).
_LAYOUT = {"tau_up": 1, "tau_down": 1, "mismatch": MAX_ROTORS, "battery_rate": 1,
           "ground_gain": 1, "ground_height": 1, "ground_radius": 1, "curve_linear": 1,
           "curve_offset": 1, "rotor_drag": 1, "rotor_drag_axial": 1, "body_drag": 3,
           "air_density": 1, "rotor_inertia": 1, "wind_mean": 3, "gust_amplitude": 1,
           "gust_frequency": GUST, "gust_phase": 3 * GUST, "thrust_gain": 1,
           "rate_damping": 3, "payload_mass": 1, "payload_length": 1, "payload_attach": 3,
           "payload_arm": 3, "payload_stiffness": 1, "payload_damping": 1, "gravity": 1,
           "com": 3, "blade_flapping": 3, "speed_gain": 1,
           "translational_lift": 1, "rotor_speed_gain": MAX_ROTORS, "body_drag_axes": 1,
           "curve_quadratic": 1}
OFFSET = {}
_n = 0
for _key, _size in _LAYOUT.items():
    OFFSET[_key] = _n
    _n += _size
WIDTH = _n
