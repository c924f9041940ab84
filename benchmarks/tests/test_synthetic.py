"""The inverse-dynamics generator (benchmarks.synthetic) refuses, when asked, a path its
vehicle's rotors cannot fly."""

import numpy as np
import pytest

from benchmarks.synthetic import (
    SLOWER,
    SPEED_BOUNDS,
    NotFlyable,
    flyable_flight,
    synthetic_flight,
)
from quadsim.vehicle.params import hover_speed, load_params


def test_a_path_the_rotors_cannot_fly_is_refused_when_asked_and_kept_as_before_otherwise():
    """At 2 m/s the crazyflie21's figure-8 (seed 3) asks its rotors for speeds outside
    SPEED_BOUNDS: flyable_only refuses it, naming the samples; the default keeps the log,
    its speeds held at a bound (the behaviour before the flag). At 1 m/s the same path is
    flown exactly: the log is the same with or without the flag."""
    params = load_params("crazyflie21")
    with pytest.raises(NotFlyable, match=r"outside 0.05-3x hover at \d+ samples"):
        synthetic_flight(params, duration=4.0, rate_hz=250.0, speed=2.0, seed=3,
                         flyable_only=True)
    kept = synthetic_flight(params, duration=4.0, rate_hz=250.0, speed=2.0, seed=3, noise=None)
    ratio = kept.rotor_speed / hover_speed(params)
    at_bound = np.isclose(ratio, SPEED_BOUNDS[0], rtol=1e-9) \
        | np.isclose(ratio, SPEED_BOUNDS[1], rtol=1e-9)
    assert np.count_nonzero(np.any(at_bound, axis=1)) > 0
    a = synthetic_flight(params, duration=4.0, rate_hz=250.0, speed=1.0, seed=3)
    b = synthetic_flight(params, duration=4.0, rate_hz=250.0, speed=1.0, seed=3,
                         flyable_only=True)
    assert np.array_equal(a.rotor_speed, b.rotor_speed)
    assert np.array_equal(a.position, b.position)


def test_flyable_flight_flies_a_path_the_rotors_cannot_fly_slower():
    """The same seed-3 path at 2 m/s: refused there and at 0.9, 0.81 and 0.729 of it (137,
    114, 69 and 17 samples held), flown exactly at SLOWER^4 x 2 m/s = 1.3122 m/s; the log is
    synthetic_flight's at that speed. A path the rotors fly is synthetic_flight's own."""
    params = load_params("crazyflie21")
    kw = dict(duration=4.0, rate_hz=250.0, seed=3)
    got = flyable_flight(params, speed=2.0, **kw)
    speed = 2.0 * SLOWER * SLOWER * SLOWER * SLOWER      # as flyable_flight steps it
    want = synthetic_flight(params, speed=speed, **kw)
    assert np.array_equal(got.rotor_speed, want.rotor_speed)
    assert np.array_equal(got.position, want.position)
    with pytest.raises(NotFlyable):
        synthetic_flight(params, speed=speed / SLOWER, flyable_only=True, **kw)
    plain = flyable_flight(params, speed=1.0, **kw)
    assert np.array_equal(plain.rotor_speed, synthetic_flight(params, speed=1.0, **kw).rotor_speed)
