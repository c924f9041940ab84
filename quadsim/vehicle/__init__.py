"""Vehicle stage: parameter sets (:mod:`~quadsim.vehicle.params`, every number
``{value, unit, source}``), rotor geometry, allocation matrix and mixer
(:mod:`~quadsim.vehicle.rotors`), feasibility guards that refuse a vehicle that cannot fly
(:mod:`~quadsim.vehicle.guards`) and the state convention with its time-series type
(:mod:`~quadsim.vehicle.state`: ``Trajectory``).

Imports :mod:`quadsim.core` and :mod:`quadsim.cad` (a set may take its mass properties and
rotor layout from the CAD assembly).
"""
