"""A wind reading carries the rotors' flapping moment (quadsim.gap.explanations.wind_moment),
judged outside its plausible range only where its interval lies outside it
(quadsim.gap.fitting.plausible_values)."""

from types import SimpleNamespace

from quadsim.gap.fitting import candidate_plausibility, plausibility, plausible_values
from quadsim.vehicle.params import load_params

LOOSE = ("blade_flapping.roll", "blade_flapping.pitch")


def _reading(values, post, loose=LOOSE):
    return SimpleNamespace(values=dict(values), post_sd=dict(post),
                           determined={k: True for k in values},
                           explanation=SimpleNamespace(loose=loose))


def test_a_loose_value_whose_interval_reaches_its_range_is_not_judged():
    params = load_params("crazyflie21")
    # -1.2e-8 +- 1.96 x 8.1e-9: the interval reaches 0, the range's lower end
    assert not plausibility("blade_flapping.roll", -1.2e-8, params)[1]
    ev = _reading({"wind.vx": 0.05, "blade_flapping.roll": -1.2e-8},
                  {"wind.vx": 0.01, "blade_flapping.roll": 8.1e-9})
    assert plausible_values(ev, params) == {"wind.vx": 0.05}
    assert candidate_plausibility(plausible_values(ev, params), params)[1]


def test_a_loose_value_outside_by_its_interval_and_an_own_value_are_judged():
    params = load_params("crazyflie21")
    # -4.5e-8 +- 1.96 x 1.24e-8 (the real nominal flights' pitch beside a wind): outside
    ev = _reading({"wind.vx": 0.05, "blade_flapping.pitch": -4.5e-8},
                  {"wind.vx": 0.01, "blade_flapping.pitch": 1.24e-8})
    kept = plausible_values(ev, params)
    assert kept == {"wind.vx": 0.05, "blade_flapping.pitch": -4.5e-8}
    assert not candidate_plausibility(kept, params)[1]
    # the blade_flapping reading's own values are never loose: judged as they are
    own = _reading({"blade_flapping.roll": -1.2e-8}, {"blade_flapping.roll": 8.1e-9}, loose=())
    assert plausible_values(own, params) == {"blade_flapping.roll": -1.2e-8}


def test_an_implausible_part_of_a_reading_of_several_effects_is_named():
    """The prior text says which parameter lies outside where a reading spans several effects
    (a wind with its flapping moment); a one-effect reading's text is as before."""
    params = load_params("crazyflie21")
    _, ok, text = candidate_plausibility({"wind.vx": 0.05, "blade_flapping.pitch": -4.5e-8},
                                         params)
    assert not ok and text.startswith("blade_flapping.pitch: plausible 0 .. 3 %"), text
    _, ok, text = candidate_plausibility({"blade_flapping.pitch": -4.5e-8}, params)
    assert not ok and text.startswith("plausible 0 .. 3 %"), text
