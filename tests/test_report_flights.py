"""The per-flight HTML page and text output (quadsim.gap.report, the CLI's notes):
the page parsed with html.parser and its tables checked cell by cell."""

from __future__ import annotations

from html.parser import HTMLParser

import pytest

from quadsim.gap.__main__ import gather_notes
from quadsim.gap.report import flights_html, write_html


class _Tables(HTMLParser):
    """Every table of a page as rows of cell texts, keyed by the heading before it; the
    texts of every element outside tables and the JSON appendix; the style sheet."""

    def __init__(self):
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.order: list[str] = []
        self.heading, self.cell, self.row, self.rows = "", None, None, None
        self.in_heading = False
        self.in_style = False
        self.appendix = False
        self.style = ""
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag in ("h1", "h2"):
            self.in_heading, self.heading = True, ""
        elif tag == "style":
            self.in_style = True
        elif tag == "details":
            self.appendix = True
        elif tag == "table":
            self.rows = []
        elif tag == "tr" and self.rows is not None:
            self.row = []
        elif tag in ("td", "th") and self.row is not None:
            self.cell = ""

    def handle_endtag(self, tag):
        if tag in ("h1", "h2"):
            self.in_heading = False
        elif tag == "style":
            self.in_style = False
        elif tag in ("td", "th") and self.cell is not None:
            self.row.append(self.cell)
            self.cell = None
        elif tag == "tr" and self.row is not None:
            self.rows.append(self.row)
            self.row = None
        elif tag == "table":
            key = self.heading or "first"
            self.tables[key] = self.rows
            self.order.append(key)
            self.rows = None

    def handle_data(self, data):
        if self.in_heading:
            self.heading += data
        if self.in_style:
            self.style += data
        if self.cell is not None:
            self.cell += data
        elif not self.in_style and not self.appendix:
            self.text.append(data)


def _parse(page: str) -> _Tables:
    parser = _Tables()
    parser.feed(page)
    return parser


def _reading(name, p, magnitude, undetermined=()):
    return {"name": name, "probability": p, "magnitude": magnitude, "log_evidence": 0.0,
            "params": {}, "ci": {}, "undetermined": list(undetermined), "fixed": {},
            "variant": ""}


def _flight(name, verdict, p, lead, others=(), symptom=None, delays=None, notes=(),
            lack=None):
    outcome = verdict if verdict in ("no_significant_gap", "unexplained") else "effect"
    return {"file": f"/data/{name}", "outcome": outcome, "verdict": verdict,
            "probability": p, "answer": f"{verdict} ({100 * p:.0f} %): {lead}.",
            "posterior": [_reading("no_difference" if outcome == "no_significant_gap"
                                   else verdict, p, lead)] + list(others),
            "lack_of_fit": lack or {}, "symptom": symptom or {},
            "signal_delays_ms": delays or {}, "notes": list(notes), "readings": [verdict],
            "differ_on": [], "separate_by": {}}


def _deficit(value):
    return {"channel": "Fz", "sign": "-", "value": value, "sigmas": 9.0,
            "text": f"Fz {100 * value / 0.363:+.1f} % of the weight"}


@pytest.fixture
def result():
    mass = "+6.1 ± 0.3 g heavier (+16.5 % of the model's 37 g)"
    flights = [
        _flight("a.csv", "mass_offset", 0.93, mass,
                [_reading("thrust_factor", 0.07, "-14 ± 1 % thrust per Ω² on all 4 rotors")],
                symptom=_deficit(-0.062), delays={"rotor": 3.1, "gyro": 0.4},
                notes=[("/data/a.csv: signal delays vs motion capture: rotor +3.1 ms, gyro "
                       "+0.4 ms (estimated; a gyro delay of 1.5 samples or more is shifted "
                       "out before fitting, the others are reported only)")]),
        _flight("b.csv", "thrust_curve", 0.6, "-17 ± 1 % thrust at the hover speed",
                [_reading("mass_offset", 0.4, "+6.3 ± 0.3 g heavier")],
                symptom=_deficit(-0.060), delays={"rotor": 2.8},
                notes=["/data/b.csv: gyro delay not resolvable (flat correlation)"]),
        _flight("c.csv", "no_significant_gap", 0.97, "no difference from the reference "
                "flights", symptom={"channel": "Mz", "sign": "+", "value": 1e-6,
                                   "sigmas": 0.4, "text": "Mz +0.001 mN m"},
                delays={"rotor": 3.0}),
        {"file": "/data/bad.csv", "outcome": "refused", "verdict": "refused",
         "answer": "Not judged: /data/bad.csv: accel: looks like g", "probability": None,
         "reason": "/data/bad.csv: accel: looks like g", "readings": [], "posterior": [],
         "notes": []},
    ]
    return {"schema": "quadsim.gap/3", "model": "crazyflie21", "mode": "per-flight",
            "reference": ["r1", "r2"],
            "reference_model": {
                "params": {"nominal_refit.thrust": 0.012, "wind.vx": -30.0},
                "se": {"nominal_refit.thrust": 0.001, "wind.vx": 1e3},
                "scatter": {"nominal_refit.thrust": 0.002, "wind.vx": 0.0},
                "identified": {"nominal_refit.thrust": True, "wind.vx": False},
                "sigma": {}, "correlation_samples": {},
                "delays_ms": {"rotor": {"mean": 3.0, "sd": 0.2, "count": 2}}},
            "flights": flights, "notes": ["only 2 reference flights: give 10 or more"],
            "verdict": {"answer": "3 flights judged against the reference flights: 1 "
                                  "mass_offset, 1 no_significant_gap, 1 thrust_curve; 1 "
                                  "refused (see each flight's reason)"}}


def test_page_opens_with_one_table_of_every_flight(result, tmp_path):
    page = write_html(tmp_path / "r.html", result).read_text()
    parsed = _parse(page)
    first = parsed.tables[parsed.order[0]]
    assert first[0] == ["flight", "verdict", "probability", "magnitude", "what remains"]
    assert first[1] == ["a.csv", "mass_offset", "93 %",
                        "+6.1 ± 0.3 g heavier (+16.5 % of the model's 37 g)",
                        "nothing beyond the reference flights"]
    assert first[2][:3] == ["b.csv", "thrust_curve", "60 %"]
    assert first[3] == ["c.csv", "no_significant_gap", "97 %", "-",
                        "nothing beyond the reference flights"]
    assert first[4] == ["bad.csv", "refused", "-", ("Not judged: /data/bad.csv: accel: looks "
                        "like g"), "/data/bad.csv: accel: looks like g"]
    # each answer once: the lead's magnitude appears in that table only, never again as text
    everywhere = "".join(parsed.text) + "".join(
        c for key in parsed.order[1:] for row in parsed.tables[key] for c in row)
    assert "+6.1 ± 0.3 g" not in everywhere
    assert "Evidence" not in page
    # what is left of the readings: the runners-up, with their magnitudes
    assert "-14 ± 1 % thrust per Ω²" in everywhere and "+6.3 ± 0.3 g heavier" in everywhere


def test_page_fits_a_1400_px_window(result, tmp_path):
    style = _parse(write_html(tmp_path / "r.html", result).read_text()).style
    assert "max-width:1400px" in style
    assert "overflow-wrap:anywhere" in style          # long cells wrap, not widen the page
    assert "white-space:pre-wrap" in style             # so does the JSON appendix


def test_delays_gathered_in_one_table_and_symptoms_grouped(result, tmp_path):
    parsed = _parse(write_html(tmp_path / "r.html", result).read_text())
    delays = parsed.tables["Signal delays against motion capture (ms)"]
    assert delays[0] == ["flight", "gyro", "rotor", "note"]
    assert delays[1] == ["references (mean ± sd)", "-", "+3.0 ± 0.2", ""]
    assert delays[2] == ["a.csv", "+0.4", "+3.1", ""]
    assert delays[3] == ["b.csv", "-", "+2.8", "gyro delay not resolvable (flat correlation)"]
    assert [row[0] for row in delays[1:]] == ["references (mean ± sd)", "a.csv", "b.csv",
                                              "c.csv"]          # the refused flight has none
    notes = "".join(parsed.text)
    assert "not resolvable" not in notes and "signal delays vs motion capture" not in notes
    assert "only 2 reference flights" in notes
    # the same -17 % deficit on two flights: one row, their verdicts side by side
    shared = parsed.tables["Shared symptoms"]
    assert shared[0] == ["symptom", "flights", "range", "mass_offset", "thrust_curve"]
    assert shared[1] == ["Fz -", "2", "Fz -17.1 % of the weight .. -16.5 % of the weight",
                         "1: a.csv", "1: b.csv"]
    assert len(shared) == 2          # c.csv's symptom is below one sigma: not a symptom


def test_undetermined_reference_values_are_not_printed(result, tmp_path):
    parsed = _parse(write_html(tmp_path / "r.html", result).read_text())
    model = parsed.tables["Reference model"]
    assert model[1] == ["nominal_refit.thrust", "0.012", "0.001", "0.002"]
    assert model[2] == ["wind.vx", "not determined by the reference flights", "-", "-"]
    assert "-30" not in "".join(c for row in model for c in row)


def test_page_without_delays_symptoms_or_runners_up(result):
    for f in result["flights"]:
        f["signal_delays_ms"], f["notes"], f["symptom"] = {}, [], {}
        f["posterior"] = f["posterior"][:1]
    body = "".join(flights_html(result))
    assert "Signal delays" not in body and "Shared symptoms" not in body
    assert "Other readings" not in body


def test_span_notes_of_many_logs_are_one_warning():
    lines = [f"/data/f{k}.csv: airborne span t 1.{k}0-4{k}.50 s kept (4{k}.40 of 50.00 s); "
             f"cut: ground 0.00-1.{k}0 s; landing 4{k}.50-50.00 s" for k in range(3)]
    lines += ["/data/f0.csv: vbat: constant", "/data/f1.csv: vbat: constant"]
    out = gather_notes(lines)
    assert out == ["/data/f0.csv: vbat: constant (and 1 more file alike)",
                   ("airborne span kept (ground, idle and landing spans cut) on 3 logs: "
                   "f0.csv 1.00-40.50 s, f1.csv 1.10-41.50 s, f2.csv 1.20-42.50 s")]


def test_summary_states_each_answer_once_and_gathers_delay_notes(result):
    from quadsim.gap.report import flights_summary

    result["notes"] += [
        f"/data/r{k}.csv: gyro: delay not resolvable from this log (the two halves give "
        f"+{k}8.6 and -9{k}.6 ms, more than 10 ms apart: filtered or delayed beyond what its "
        "partner signal can time)" for k in range(2)]
    result["notes"] += [
        f"/data/r{k}.csv: signal delays vs motion capture: rotor +3.{k} ms (estimated; a gyro "
        "delay of 1.5 samples or more is shifted out before fitting, the others are reported "
        "only)" for k in range(2)]
    lines = flights_summary(result).splitlines()
    assert lines[2] == "  a.csv: mass_offset (93 %): +6.1 ± 0.3 g heavier (+16.5 % of the " \
                       "model's 37 g)."
    assert lines[5] == "  bad.csv: Not judged: /data/bad.csv: accel: looks like g"
    notes = [line for line in lines if line.startswith("note: ")]
    assert notes == [
        "note: only 2 reference flights: give 10 or more",
        ("note: gyro: delay not resolvable on 2 flights, the two halves of each log disagree "
        "(more than 10 ms apart: filtered or delayed beyond what its partner signal can time): "
        "r0.csv (+08.6 / -90.6 ms), r1.csv (+18.6 / -91.6 ms)"),
        ("note: signal delays vs motion capture (estimated; a gyro delay of 1.5 samples or more "
        "is shifted out before fitting, the others are reported only): r0.csv rotor +3.0 ms; "
        "r1.csv rotor +3.1 ms")]
