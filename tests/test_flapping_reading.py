"""Blade flapping as a per-flight reading (issues 45 and 47): a flapping every reference
shares is normal (the discrepancy term and practical significance), a flight that flaps
more than its references is named ``blade_flapping`` with its size."""

import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.effects import make_effect
from quadsim.effects.blade_flapping import _scale
from quadsim.gap import diagnose_per_flight
from quadsim.vehicle.params import load_params

EFFECTS = ["mass_offset", "com_offset", "body_drag", "blade_flapping"]


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _logs(cf, effects, seeds):
    return [synthetic_flight(cf, effects, seed=s, duration=4.0, speed=1.5) for s in seeds]


def _flap(k):
    return [make_effect("blade_flapping", roll=k, pitch=k)]


def test_blade_flapping_is_a_per_flight_reading(cf):
    """The effect declares one reading (roll and pitch free), after the other readings."""
    from quadsim.effects.blade_flapping import BladeFlapping
    from quadsim.gap.explanations import reading_effects

    assert [r.fitted for r in BladeFlapping.facts.readings] == [("roll", "pitch")]
    assert reading_effects()[-1] is BladeFlapping


def test_a_flapping_the_references_share_is_normal_and_more_of_it_is_named(cf):
    """Five references and both tested flights flap with k = the effect's typical scale
    (7.3e-8 kg m/rad on the Crazyflie: 0.45 mN m per m/s at the hover speed, the size a real
    Crazyflie's nominal flights read); the flight with only that is no_significant_gap, the
    one with 4 k is named blade_flapping with roll and pitch about 3 k beyond the references'
    (their shared k is in the reference model's discrepancy, not in the reading)."""
    k = _scale(cf)
    reference = _logs(cf, _flap(k), (60, 61, 62, 63, 64))
    tested = [*_logs(cf, _flap(k), (65,)), *_logs(cf, _flap(4 * k), (66,))]
    result = diagnose_per_flight(tested, reference, cf, effects=EFFECTS)
    flights = result["flights"]
    assert flights[0]["outcome"] == "no_significant_gap", flights[0]["answer"]
    assert flights[1]["verdict"] == "blade_flapping", flights[1]["answer"]
    for axis in ("roll", "pitch"):
        assert flights[1]["params"][f"blade_flapping.{axis}"] == pytest.approx(3 * k, rel=0.35)
    assert result["reference_model"]["self_check"]["clean"]
