"""quadsim: CAD parts of a small quadrotor -> MuJoCo model, analytic reference, rerun viewer,
and sim-to-real gap diagnosis.

Conventions: SI units inside; world z up; body x forward, y left, z up; quaternions
scalar-first (w, x, y, z), body to world. See :mod:`quadsim.vehicle.params` and
:mod:`quadsim.vehicle.state`.
"""

__version__ = "0.1.0"
