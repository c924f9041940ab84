"""The calibration's torque-side Jacobian from the plain one (quadsim.gap.calibrate.
_side_jacobian, issue 43 item 7) against the torque side probed column by column
(quadsim.gap.reference.jacobian): the same base bit for bit, the same columns to the
differences' round-off."""
import dataclasses

import numpy as np

from benchmarks.synthetic import synthetic_flight
from quadsim.effects import make_effect
from quadsim.gap.calibrate import (
    POOLED,
    Reference,
    TorqueSide,
    _side_jacobian,
    jacobian,
    per_flight_candidate,
)
from quadsim.gap.diagnose import prepare
from quadsim.vehicle.params import load_params


def test_the_side_jacobian_is_the_probed_one():
    params = load_params("crazyflie21")
    log = synthetic_flight(params, [make_effect("inertia_error", xx=0.2, yy=0.1)], seed=3,
                           duration=4.0)
    states = prepare([log], params)[0].fit
    cand = per_flight_candidate(True, False)
    names = list(cand.parameter_names)
    theta = np.zeros(len(names))
    for name, value in (("inertia_error.xx", 0.1), ("inertia_error.yy", 0.05),
                        ("rate_damping.x", 2e-6), ("rotor_drag.coefficient", 1e-6),
                        ("wind.vx", 0.2), ("motor_lag.time_constant", 0.03)):
        theta[names.index(name)] = value
    chans = 6 + params.rotor_count
    sigma = np.r_[np.full(3, 0.02), np.full(3, 1e-4), np.full(params.rotor_count, 20.0)]
    plain = Reference(params, True, cand, theta, np.zeros_like(theta), np.zeros_like(theta),
                      sigma, np.full(chans, 2.0), np.zeros(chans), 1.0, 1, {}, [], {})
    side = dataclasses.replace(plain, side=TorqueSide(1.0 / float(states.t[1] - states.t[0])))
    free = [j for j, n in enumerate(names) if n not in POOLED]
    jac_plain, base_plain = jacobian(states, plain, free, cand.effects, with_base=True)
    probed, base = jacobian(states, side, free, cand.effects, with_base=True)
    jac, new_base = _side_jacobian(states, side, free, (jac_plain, base_plain))
    assert np.array_equal(new_base, base)
    norms = np.linalg.norm(probed, axis=0)
    assert np.all(norms > 0)
    assert np.all(np.linalg.norm(jac - probed, axis=0) <= 1e-7 * norms)
    for j, n in enumerate(n for k, n in enumerate(names) if k in free):
        if n.startswith("inertia_error."):      # moves the vehicle's inertia: probed alike
            assert np.array_equal(jac[:, j], probed[:, j])
    # the side does change the roll/pitch columns (the test is not of two equal paths)
    assert np.all(np.isfinite(probed))
    assert np.linalg.norm(jac_plain - probed) > 1e-3 * np.linalg.norm(probed)
