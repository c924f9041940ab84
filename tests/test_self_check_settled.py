"""The references' self-check reads a false alarm's readings on every reference before it
is final (issue #47 item 3, :func:`quadsim.gap.calibrate.settled_self_check`): a reading
the screen left screened on the other references is no scale of practical significance, so
a reference whose reading the screen fitted on fewer than 2 others was an alarm the exact
leave-one-out did not raise (the nano-drone benchmark's square run1)."""

from types import SimpleNamespace

import numpy as np

from quadsim.gap.calibrate import (
    PRACTICAL_Z,
    negligible,
    self_check_of,
    settled_self_check,
    to_refine,
)

#: each reference's true translational-lift reading (kg/m) and its posterior SD; e is a
#: reference whose lift is far beyond the others' (a real difference)
TRUE = {"a": 0.00090, "b": 0.00070, "c": 0.00080, "d": 0.00085, "e": 0.00500}
SD = 0.0001
KEY = "translational_lift.k_h"


def _row(name, value, screened):
    return SimpleNamespace(name=name, explanation=SimpleNamespace(variant="", parts=()),
                           values={KEY: value} if name != "no_difference" else {},
                           post_sd={KEY: SD} if name != "no_difference" else {},
                           determined={KEY: True} if name != "no_difference" else {},
                           log_z=0.0, screened=screened, slow=None)


def _item(ref, screened):
    """A reference's rows: "no difference" and a lift reading, screened where ``screened``
    (its screened value is the step's, 0 here: not the flight's value)."""
    return SimpleNamespace(name=ref, rows=[_row("no_difference", 0.0, False),
                                           _row("translational_lift",
                                                0.0 if screened else TRUE[ref], screened)])


def _judge(item, check):
    """An alarm named translational_lift unless the reading is negligible against the
    others' scale (calibrate.negligible: the practical-significance rule)."""
    lift = item.rows[1]
    if lift.screened or negligible(lift, check):
        return SimpleNamespace(outcome="no_significant_gap", name="no_significant_gap",
                               lack_of_fit={}, differ_on=())
    return SimpleNamespace(outcome="effect", name="translational_lift", lack_of_fit={},
                           differ_on=("Fz",))


def _refine(calls):
    def refine(item, wanted):
        calls.append((item.name, frozenset(wanted)))
        rows = [_row(r.name, TRUE[item.name], False) if r.screened and r.name in wanted
                else r for r in item.rows]
        return SimpleNamespace(name=item.name, rows=rows)
    return refine


def _items():
    # the screen fitted the lift on a and e only (where it could matter)
    return [_item(n, n in ("b", "c", "d")) for n in TRUE]


def test_an_alarm_without_the_others_readings_is_read_again_and_cleared():
    names = list(TRUE)
    items = _items()
    cheap = self_check_of(names, [i.rows for i in items],
                          lambda j, c: _judge(items[j], c))
    # before: a's scale is the others' fitted readings, e's alone: no scale (fewer than 2),
    # the statistical rule alone, an alarm; e's likewise (a's alone)
    assert [n for n, _, _ in cheap.false_alarms] == ["a", "e"]
    assert to_refine(names, [i.rows for i in items], cheap) == {"translational_lift"}
    calls = []
    settled = settled_self_check(names, items, rows_of=lambda i: i.rows, judge_of=_judge,
                                 refine=_refine(calls))
    # every reference's lift is now a reading: the scale of each holds the other 4
    spread = settled.spreads[("translational_lift", "")][KEY]
    assert spread.count == 5
    assert spread.mean == np.mean(list(TRUE.values()))
    # one refinement pass, every reference offered the one reading
    assert sorted(n for n, _ in calls) == names
    assert {w for _, w in calls} == {frozenset({"translational_lift"})}
    # e stays an alarm (its lift is beyond the others' 2-SD band); a-d clear
    assert [n for n, _, _ in settled.false_alarms] == ["e"]


def test_the_settled_check_agrees_with_every_reading_fitted():
    """The settled self-check gives each reference the verdict it gets where the screen had
    fitted every reference's lift (the full fit: the exact scale)."""
    names = list(TRUE)
    full = [_item(n, False) for n in names]
    exact = self_check_of(names, [i.rows for i in full], lambda j, c: _judge(full[j], c))
    settled = settled_self_check(names, _items(), rows_of=lambda i: i.rows, judge_of=_judge,
                                 refine=_refine([]))
    assert settled.verdicts == exact.verdicts
    # and a's lift is negligible against its others' scale by the closed form
    others = [TRUE[n] for n in names if n != "a"]
    var = np.var(others, ddof=1)
    sd = np.sqrt(max(var - SD ** 2, min(1.0, np.sqrt(2 / 3)) * var))
    mean_se = np.sqrt(var / 4)
    assert abs(TRUE["a"] - np.mean(others)) - 1.96 * np.hypot(SD, mean_se) <= PRACTICAL_Z * sd


def test_a_clean_check_refits_nothing():
    """No alarm: nothing read again (the check stays as cheap as it was)."""
    names = ["a", "b", "c", "d"]
    items = [_item(n, False) for n in names]
    calls = []
    check = settled_self_check(names, items, rows_of=lambda i: i.rows, judge_of=_judge,
                               refine=_refine(calls))
    assert check.false_alarms == () and calls == []


def test_to_refine_takes_only_an_alarms_fitted_readings():
    """The readings to read everywhere: an alarmed reference's rows fitted to convergence,
    "no difference" and screened rows aside; a reference that is no alarm adds none."""
    rows = [[_row("no_difference", 0.0, False), _row("translational_lift", 1e-3, False),
             _row("mass_offset", 0.0, True)],
            [_row("no_difference", 0.0, False), _row("rotor_drag", 1e-3, False)]]
    check = SimpleNamespace(false_alarms=(("x", "translational_lift", ("Fz",)),))
    assert to_refine(["x", "y"], rows, check) == {"translational_lift"}
    assert to_refine(["x", "y"], [None, rows[1]], check) == set()


def test_the_nanodrone_square_run1_cheap_and_exact_leave_one_out_agree():
    """The case that raised it (real data; skips without ../shared/data): the nano-drone
    benchmark's 9 training runs (runs 1-3, never its test runs) as references. Judged
    against the other 8 calibrated without it (the exact leave-one-out), square run1 is
    no_significant_gap; the self-check (the cheap one) now says the same, where it named it
    translational_lift before (its lift read on 1 of the other 8 only: no scale). Square
    run2 stays an alarm of the self-check, as the exact leave-one-out (unexplained) agrees."""
    from pathlib import Path

    import pytest

    from quadsim.gap import diagnose_per_flight
    from quadsim.logs.flightlog import load_log
    from quadsim.vehicle.params import load_params

    root = Path(__file__).resolve().parents[1]
    runs = sorted((root / ".." / "shared" / "data" / "nanodrone_cf21bl" / "train")
                  .glob("*_run[123].csv.gz"))
    if len(runs) != 9:
        pytest.skip("nano-drone training runs not found")
    params = load_params(root / "models" / "nanodrone_cf21bl.toml")
    logs = [load_log(p, warn=False) for p in runs]
    j = next(k for k, p in enumerate(runs) if p.name.startswith("square_20251017_run1"))
    cheap = diagnose_per_flight([], logs, params)["reference_model"]["self_check"]
    alarms = {Path(a["flight"]).name: a["verdict"] for a in cheap["false_alarms"]}
    assert alarms == {"square_20251017_run2.csv.gz": "rotor_drag"}, alarms
    exact = diagnose_per_flight([logs[j]], logs[:j] + logs[j + 1:], params)["flights"][0]
    assert exact["outcome"] == "no_significant_gap", exact["answer"]
