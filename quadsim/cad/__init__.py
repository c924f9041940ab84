"""CAD stage: the parts manifest and meshes (:mod:`~quadsim.cad.assembly`), STEP parts
through trimesh + cascadio (:mod:`~quadsim.cad.step`) and the one function that owns mass
properties (:mod:`~quadsim.cad.massprops`: mass, CoM and inertia from the meshes, SI units).

Imports only :mod:`quadsim.core`. The MJCF text is written by :mod:`quadsim.sim.mjcf` (it
needs a parameter set's rotors); the command is ``python -m quadsim.build_mjcf``.
"""
