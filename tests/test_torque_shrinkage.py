"""A reading that scales every rotor's wrench (a thrust factor) gains on the torque channels
from the logged speeds' noise alone (errors in variables): that gain is bounded
(quadsim.gap.judge.torque_shrinkage) and taken off before a declared confusable pair is read
as told apart (quadsim.gap.logcheck._unseparated_rivals). Closed forms."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.judge import TORQUE_CHANNELS, torque_shrinkage
from quadsim.gap.logcheck import SEPARATED, _unseparated_rivals
from quadsim.gap.result import Reading


def _ev(values, ms):
    return SimpleNamespace(values=dict(values), ms=np.asarray(ms, float))


def test_the_bound_is_half_n_over_tau_times_the_shrunk_share_of_the_torque_mean_square():
    ms = np.array([1.0, 1.0, 1.0, 0.27, 0.27, 0.001, 1.4, 1.4, 1.4, 1.3])
    reference = SimpleNamespace(tau=np.full(10, 5.2))
    s = 1.0 - 0.067
    expected = sum(0.5 * 1160 / 5.2 * (1 - s * s) / (s * s) * ms[c] for c in TORQUE_CHANNELS)
    got = torque_shrinkage(_ev({"thrust_factor.change": -0.067}, ms), reference, 1160)
    assert got == pytest.approx(expected, rel=1e-12)
    assert got == pytest.approx(8.9, abs=0.1)    # the testbed's +60 g: 8.7 observed
    # nothing to owe: a mass, a larger thrust factor (its scale raises the noise), none at all
    assert torque_shrinkage(_ev({"mass_offset.mass": 0.06}, ms), reference, 1160) == 0.0
    assert torque_shrinkage(_ev({"thrust_factor.change": 0.05}, ms), reference, 1160) == 0.0
    assert torque_shrinkage(_ev({}, ms), reference, 1160) == 0.0


def _verdict(lead_logz, rival_logz):
    lead = Reading("thrust_factor", 0.99, "-6.7 % thrust", lead_logz,
                   {"thrust_factor.change": -0.067})
    rival = Reading("mass_offset", 0.0, "+60 g", rival_logz, {"mass_offset.mass": 0.06})
    return SimpleNamespace(name="thrust_factor", readings=("thrust_factor",),
                           posterior=(lead, rival))


def test_a_margin_the_speeds_noise_could_give_does_not_tell_the_pair_apart():
    """The testbed's +60 g: the thrust factor 10.7 log units above the mass, 8.9 of them
    what its scale can owe to the speeds' noise: 1.8 left, within ln 150 (5.0): the mass is
    stated beside the name. With nothing owed, the pair is told apart."""
    verdict = _verdict(-1108.3, -1119.0)
    assert _unseparated_rivals(verdict, SEPARATED) == []
    owed = {("thrust_factor", ""): 8.9}
    (rival, hint), = _unseparated_rivals(verdict, SEPARATED, owed)
    assert rival.name == "mass_offset" and "weigh the vehicle" in hint
    # a margin beyond what the noise could give stays a separation
    assert _unseparated_rivals(_verdict(-1100.0, -1119.0), SEPARATED, owed) == []
    # a rival's own bound is not taken off it (it may be as good as it looks): a mass named
    # 3 units above a thrust factor keeps it beside, whatever the factor could owe
    lead = Reading("mass_offset", 0.9, "+60 g", -1105.0, {"mass_offset.mass": 0.06})
    rival = Reading("thrust_factor", 0.1, "-6.7 % thrust", -1108.0,
                    {"thrust_factor.change": -0.067})
    named_mass = SimpleNamespace(name="mass_offset", readings=("mass_offset",),
                                 posterior=(lead, rival))
    (kept, _), = _unseparated_rivals(named_mass, SEPARATED, owed)
    assert kept.name == "thrust_factor"


def test_the_words_say_the_pair_is_stated_on_the_noises_account():
    """A thrust factor named 10.7 log units above the mass, 8.9 of them what its scale may
    owe to the speeds' noise: the mass stated beside it, tentative, and the answer says why;
    with nothing owed the verdict is returned as it was."""
    from quadsim.gap.logcheck import confusable_note
    from quadsim.gap.result import Verdict

    posterior = (Reading("thrust_factor", 0.99, "-6.7 % thrust", -1108.3,
                         {"thrust_factor.change": -0.067}),
                 Reading("mass_offset", 0.0, "+60 g heavier", -1119.0,
                         {"mass_offset.mass": 0.06}))
    named = Verdict("effect", "thrust_factor", "thrust_factor (99 %): -6.7 %.", 0.99,
                    posterior=posterior, readings=("thrust_factor",))
    pose = SimpleNamespace(has_pose=True)
    assert confusable_note(named, pose) is named
    noted = confusable_note(named, pose, {("thrust_factor", ""): 8.9})
    assert noted.tentative and noted.readings == ("thrust_factor", "mass_offset")
    assert ("once the name's evidence is taken as up to 8.9 log units less (what its scale of "
            "every rotor's torque may owe to the logged rotor speeds' noise: errors in "
            "variables).") in noted.answer
    assert "prior's centre" not in noted.answer
