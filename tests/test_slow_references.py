"""References flown slowly (held in place, a wind tunnel's or a hover's small steps): their drag
taken as a quadratic law needs an area no airframe has, and such a law is not offered
(quadsim.gap.calibrate._drag_refit); before, its equivalent area became a fixed value of every
reading under it, refused as an effect, and with it every flight judged against them."""

from __future__ import annotations

import warnings

import pytest

from _helpers import MOCAP_NOISE

pytestmark = pytest.mark.xdist_group("test_slow_references")


def _flight(cf, seed: int):
    from quadsim.effects import EffectSet, make_effect
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel

    # a rotor drag (linear in air speed) and a vertical body drag on the air speed, shared
    shared = EffectSet((make_effect("rotor_drag", coefficient=1.9e-6),
                        make_effect("body_drag", cd_area_vertical=0.3)))
    return generate_flight(cf, "steps", shared, SensorModel(noise=MOCAP_NOISE), seed,
                           duration=4.0, speed=0.3, size=0.2, height=0.5)[0]


def test_references_held_in_place_offer_no_law_beyond_an_airframes_area():
    """Four references stepping 0.2 m at 0.3 m/s at a constant height (the vertical air
    speed a small fraction of the horizontal one): their shared vertical drag on the air
    speed, read per body axis on the vertical air speed alone, needs an area many times its
    own (measured: the least-squares equivalent 2.8 m^2 on the 0.21 m^2 they share, beyond
    body drag's 1 m^2): the law per body axis keeps their vertical drag as it is (no
    ``cd_area_vertical`` among its fixed values); every law's fixed values build as an
    effect; a flight flown alike is judged (was refused: "cd_area_vertical = 2.82 m^2
    outside the plausible range")."""
    from quadsim.core.errors import QuadsimWarning
    from quadsim.effects import make_effect
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare
    from quadsim.gap.explanations import quadratic_laws
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        reference = calibrate(prepare([_flight(cf, s) for s in range(4)], cf), cf)
        verdict = judge_one(_flight(cf, 9), reference)
    assert reference.values()["body_drag.cd_area_vertical"] > 0.05
    assert reference.quadratic_vertical_axes == 0.0
    laws = quadratic_laws(reference)
    assert len(laws) == 2
    for _, fixed, area in laws:
        assert "cd_area_vertical" not in fixed
        assert 0.0 < area <= 1.0
        make_effect("body_drag", **fixed, cd_area=area)      # raises outside the range
    assert verdict.outcome != "refused", verdict.answer
    assert "plausible range" not in verdict.answer
