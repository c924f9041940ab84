"""Practical significance at the flight's place (issue 47): the references' readings of an
explanation follow their trend along the envelope axis beyond the outermost reference, as the
lack-of-fit baseline does (quadsim.gap.calibrate.placed, used by both modes)."""

from types import SimpleNamespace

import numpy as np
import pytest

from quadsim.gap.calibrate import (
    PRACTICAL_Z,
    SelfCheck,
    against_text,
    negligible,
    placed,
    readings,
    spreads,
)
from quadsim.gap.reference import Position, envelope_of

KEY = ("body_drag", "")
AREA = "body_drag.area"


def _evidence(value, sd):
    return SimpleNamespace(name="body_drag", explanation=SimpleNamespace(variant="", parts=()),
                           values={AREA: value}, post_sd={AREA: sd}, determined={AREA: True},
                           log_z=0.0)


def _references(offsets=(0.2, -0.1, -0.3, 0.25, 0.05, -0.1)):
    """Six references flown at RMS speeds 0.5-1.0 m/s (log places along the speed axis)
    whose drag-area reading grows with speed, 4 cm^2 per log unit, scatter 0.2 cm^2 about
    the line; each reading's posterior SD 0.3 cm^2."""
    speed = np.log(np.linspace(0.5, 1.0, 6))
    coords = np.column_stack([speed, np.full(6, np.log(2.0)), np.full(6, np.log(1.0))])
    area = 1e-4 * (2.0 + 4.0 * (speed - speed.mean()) + np.asarray(offsets))
    rows = [[_evidence(v, 0.3e-4)] for v in area]
    per = [readings(r) for r in rows]
    check = SelfCheck(tuple(f"ref{j}" for j in range(6)), ("no_significant_gap",) * 6, (),
                      spreads(per), None, tuple(per))
    envelope = envelope_of(coords, np.zeros((6, 1)), np.ones((6, 1)), np.array([True]),
                           np.zeros((6, 1)))
    return coords, area, check, envelope


def _at(envelope, speed):
    """A reference model placed at a flight of RMS speed ``speed`` (m/s)."""
    x = np.array([np.log(speed), np.log(2.0), np.log(1.0)])
    u = float(x @ envelope.trend.axis)
    return SimpleNamespace(envelope=envelope,
                           place=Position(x, max(0.0, x[0] - envelope.high[0]), "speed", u, ""))


def test_beyond_the_references_a_reading_is_compared_with_their_trend_there():
    coords, area, check, envelope = _references()
    fast = _at(envelope, 1.6)                  # 1.6x the fastest reference: e = ln 1.6
    edge = np.log(1.6)
    assert envelope.trend.axis @ [1, 0, 0] == pytest.approx(1.0)
    here = placed(check, fast).spreads[KEY][AREA]
    # an independent least-squares line of the readings on the log speeds
    b, a = np.polyfit(coords[:, 0], area, 1)
    rest = area - (a + b * coords[:, 0])
    var_b = rest @ rest / 4 / np.sum((coords[:, 0] - coords[:, 0].mean()) ** 2)
    s = check.spreads[KEY][AREA]
    assert here.mean == pytest.approx(area.mean() + b * edge)
    assert here.mean_se == pytest.approx(np.sqrt(s.mean_se ** 2 + var_b * edge ** 2))
    assert here.sd == pytest.approx(np.sqrt(s.sd ** 2 + (b ** 2 + var_b) * edge ** 2))
    assert b == pytest.approx(4e-4, rel=0.15)
    # placed once: the result keeps no readings, and placing it again leaves it
    once = placed(check, fast)
    assert once.per == () and placed(once, fast) is once
    assert here.edge == pytest.approx(edge) and s.edge == 0.0
    words = against_text(_evidence(1e-3, 0.3e-4), once)
    assert words == ("area +0.001 against the references' (on their trend, at this flight's "
                     f"place beyond them) {here.mean:+.2g} ± {here.sd:.2g} "
                     f"({(1e-3 - here.mean) / here.sd:.3g} SDs)")
    assert "on their trend" not in against_text(_evidence(1e-3, 0.3e-4), check)

    # a no-effect flight flown faster reads what the trend predicts there: no difference
    # at its place, though a difference against the references' mean (the rule before)
    predicted = a + b * np.log(1.6)
    assert not negligible(_evidence(predicted, 0.3e-4), check)
    assert negligible(_evidence(predicted, 0.3e-4), placed(check, fast))
    # a real change on top of the trend: beyond the widened band, named; the band is
    # about twice the trend's own move there (4 cm^2 x ln 1.6 = 1.9 cm^2)
    band = PRACTICAL_Z * here.sd + 1.96 * np.hypot(0.3e-4, here.mean_se)
    assert band == pytest.approx(5.2e-4, abs=0.3e-4)
    assert not negligible(_evidence(predicted + 8e-4, 0.3e-4), placed(check, fast))
    assert not negligible(_evidence(here.mean + band + 1e-6, 0.3e-4), placed(check, fast))
    assert negligible(_evidence(here.mean + band - 1e-6, 0.3e-4), placed(check, fast))


def test_inside_the_envelope_or_without_a_trend_the_references_mean_holds():
    _, _, check, envelope = _references()
    inside = _at(envelope, 0.8)
    assert placed(check, inside) is check
    assert placed(check, SimpleNamespace(envelope=envelope, place=None)) is check
    assert placed(check, SimpleNamespace(envelope=SimpleNamespace(trend=None, coords=None),
                                         place=_at(envelope, 1.6).place)) is check
    # readings kept on two references only: no trend measured, the mean holds
    per = tuple({KEY: r[KEY]} if j < 2 else {} for j, r in enumerate(check.per))
    few = SelfCheck(check.flights, check.verdicts, (), spreads(list(per)), None, per)
    assert placed(few, _at(envelope, 1.6)).spreads == few.spreads
    # and its size is stated against the references' own readings, not a trend
    assert "on their trend" not in against_text(_evidence(1e-3, 0.3e-4),
                                                placed(few, _at(envelope, 1.6)))
