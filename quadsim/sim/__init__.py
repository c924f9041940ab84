"""Simulation stage: the analytic Newton-Euler engine (:mod:`~quadsim.sim.analytic`), the
MuJoCo engine and its MJCF (:mod:`~quadsim.sim.mujoco_engine`, :mod:`~quadsim.sim.mjcf`),
their compiled fast path (:mod:`quadsim.sim.compiled`, which depends on the engines and never
the other way round), one front door ``simulate`` (:mod:`~quadsim.sim.engines`), hover
linearisation and LQR (:mod:`~quadsim.sim.linear`), the geometric tracking controller
(:mod:`~quadsim.sim.controllers`) and reference paths (:mod:`~quadsim.sim.paths`).

Imports :mod:`quadsim.core`, :mod:`quadsim.vehicle` and :mod:`quadsim.effects`.
"""
