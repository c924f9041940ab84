"""Held out, a name beside a systematic remainder is never confident (issue 47: out of the
library never a confident wrong name). The remainder says part of the gap is outside the
library, so the name may be a stand-in for it; per flight such a lead is ``unexplained``.
The self-generated benchmark's testbed blade flapping came out ``cable_payload+mass_offset``
with Mx 9x, My 12x left (quadsim.gap.judge.judge_heldout)."""

from types import SimpleNamespace

import numpy as np

from quadsim.gap.evidence import Evidence
from quadsim.gap.explanations import Explanation
from quadsim.gap.judge import judge_heldout, remainder
from quadsim.gap.result import Reading
from quadsim.vehicle.params import load_params

DT = 0.01
KEY = "mass_offset.mass"


def _decision(slow: float, seed: int = 0):
    """A mass reading (+5 g, 99 %) whose residuals on two training flights and one held-out
    flight (600 samples, unit noise on 6 channels) carry ``slow`` x sin(2 pi 0.3 t) on Mx
    (the same on every flight: it carries over, so only the remainder can see it)."""
    rng = np.random.default_rng(seed)
    t = DT * np.arange(600)

    def flight():
        r = rng.standard_normal((600, 6))
        r[:, 3] += slow * np.sin(2 * np.pi * 0.3 * t)
        return r

    expl = Explanation("mass_offset", "", (("mass_offset", {}, ("mass",)),), (0.0,), (0.01,))
    train = Evidence(expl, {KEY: 0.005}, {KEY: 0.0002}, {KEY: 0.01}, {KEY: True}, 0.0,
                     np.ones(6))
    lead = SimpleNamespace(train=train, total=train, train_residuals=[flight(), flight()],
                           held_residuals=[flight()])
    entry = {"name": "mass_offset", "params": {KEY: 0.005}, "ci": {KEY: 0.0004},
             "fixed": {}, "reduction": 0.9, "heldout_gap_after": 1.0,
             "identifiable": {KEY: True}, "significant": {KEY: True}}
    row = Reading("mass_offset", 0.99, "+5 g heavier", 0.0, {KEY: 0.005}, {KEY: 0.0004}, (),
                  {}, "")
    null_row = Reading("no_difference", 0.01, "no difference", -10.0, {}, {}, (), {}, "")
    return SimpleNamespace(
        rows=(row, null_row), lead_name="mass_offset", lead=lead, null=None,
        implausible=(), consistency=None, shown="mass_offset",
        probability={"mass_offset": 0.99, "no_difference": 0.01},
        entry=lambda name: entry if name == "mass_offset" else None)


def _judge(decision):
    params = load_params("crazyflie21")
    reference = SimpleNamespace(params=params, sigma=np.ones(6), tau=np.ones(6), rotor=False)
    residuals = decision.lead.train_residuals + decision.lead.held_residuals
    verdict, _ = judge_heldout(decision, reference, before=decision.lead.held_residuals,
                               after=decision.lead.held_residuals, dt=DT)
    return verdict, remainder(residuals, reference, DT)


def test_a_name_with_a_systematic_remainder_is_tentative():
    verdict, left = _judge(_decision(slow=0.5))
    # the slow part's mean square about 0.125 against 1/51 from unit white noise: 6x
    assert list(left) == ["Mx"] and 4.0 < left["Mx"][1] < 9.0
    assert verdict.outcome == "effect" and verdict.name == "mass_offset"
    assert verdict.probability == 0.99
    assert verdict.tentative
    assert "Tentative" in verdict.answer and "outside the library" in verdict.answer


def test_the_same_name_without_a_remainder_stays_confident():
    verdict, left = _judge(_decision(slow=0.0))
    assert left == {}
    assert verdict.outcome == "effect" and not verdict.tentative
    assert "Tentative" not in verdict.answer
