"""The report an engineer reads (quadsim.gap.page, .plots, .traces): its structure parsed with
html.parser (the figures are inline SVG, every table cell is a name or a value with its
unit, the first screen answers per flight), the residual's share removed by closed form, and
the series of a judged synthetic flight against the physics of its known payload."""

from __future__ import annotations

import dataclasses
import re
import types
import warnings
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from quadsim.gap.page import page
from quadsim.gap.result import Diagnosis, Reading, Series, Verdict
from quadsim.gap.words import batch_answer, residual_text

CHANNELS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz", "rotor_1", "rotor_2", "rotor_3", "rotor_4")
SIGMA = np.array([1e-3, 1.4e-3, 3.8e-3, 1.4e-4, 1.8e-4, 1.8e-5, 12.0, 9.0, 11.0, 12.0])
#: a number in a cell must come with one of these (the report's units, words for ratios)
UNIT = re.compile(r"(%|\d\s*x\b|x \(|\b(ms|mN|N|N m|g|kg|m|s|m/s|rad|rad/s|V|deg|cm²|m\^2|"
                  r"kg m\^2|kg/rad|N m s/rad|relative|flights)\b|\(relative\))")


def _series(name: str, before, after, seed: int = 0, n: int = 500) -> Series:
    """Residuals of ``before`` and ``after`` (scalars or (C,)) times the references' RMS,
    per channel exactly."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    states = types.SimpleNamespace(t=t, position=np.zeros((n, 3)),
                                   velocity=rng.normal(size=(n, 3)),
                                   quat=np.tile([1.0, 0, 0, 0], (n, 1)),
                                   body_rate=np.zeros((n, 3)),
                                   rotor_speed=2000 + 50 * rng.normal(size=(n, 4)))
    params = types.SimpleNamespace(thrust_factor=1e-8)
    noise = rng.normal(size=(n, len(CHANNELS)))
    noise /= np.sqrt(np.mean(noise ** 2, axis=0))          # unit RMS exactly
    before, after = np.asarray(before, float), np.asarray(after, float)
    return Series(t, before * SIGMA * noise, after * SIGMA * noise, CHANNELS, name, states,
                  params, (), SIGMA)


#: flight_110's residual per channel (times the references' RMS): Fz 4 before, 1.5 after
B110 = np.array([2, 2, 4, 2, 2, 2, 1, 1, 1, 1], float)
A110 = np.array([1, 1, 1.5, 1, 1, 1, 1, 1, 1, 1], float)
#: flight_102's: 6 everywhere but Fy 7 before; Fy 5.1 and 1 elsewhere after
B102 = np.array([6, 7, 6, 6, 6, 6, 6, 6, 6, 6], float)
A102 = np.array([1, 5.1, 1, 1, 1, 1, 1, 1, 1, 1], float)


def _reading(name, p, magnitude, params=None, ci=None):
    return Reading(name, p, magnitude, 0.0, params or {}, ci or {})


def _flights() -> tuple:
    mass = _reading("mass_offset", 0.93, "+6.1 ± 0.3 g heavier (+16.5 % of the model's 37 g)",
                    {"mass_offset.mass": 0.0061}, {"mass_offset.mass": 0.0003})
    thrust = _reading("thrust_factor", 0.07, "-14 ± 1 % thrust per Ω² on all 4 rotors")
    cable = _reading("cable_payload", 1.0, "a +4.6 ± 0.18 g payload hanging on a cable",
                     {"cable_payload.mass": 0.0046, "cable_payload.length": 0.47},
                     {"cable_payload.mass": 0.00018, "cable_payload.length": 0.0055})
    null = _reading("no_difference", 0.92, "no difference from the reference flights")
    deficit = {"channel": "Fz", "sign": "-", "value": -0.06, "sigmas": 9.0,
               "text": "Fz -16.5 % of the weight"}
    return (
        Verdict("effect", "mass_offset", "mass_offset (93 %): +6.1 ± 0.3 g heavier.", 0.93,
                posterior=(mass, thrust), params=mass.params, ci=mass.ci,
                file="/data/mixed/flight_110.csv.gz", symptom=deficit,
                differ_on=("Fz", "Mx"), signal_delays_ms={"gyro": -5.7, "rotor": -12.3},
                series=_series("flight_110.csv.gz", B110, A110)),
        Verdict("unexplained", "unexplained", "Not in the library: after the most probable "
                "reading (cable_payload, 100 %) the residual stays beyond the reference "
                "flights' on Fy at 5.1x their typical RMS.", 1.0, posterior=(cable,),
                lack_of_fit={"Fy": 5.1}, file="/data/mixed/flight_102.csv.gz",
                symptom=dict(deficit, value=-0.05, text="Fz -13.9 % of the weight"),
                series=_series("flight_102.csv.gz", B102, A102, seed=1)),
        Verdict("no_significant_gap", "no_significant_gap", "No difference from the "
                "reference flights (92 %).", 0.92, posterior=(null,),
                file="/data/nominal/flight_19.csv.gz", series=_series("flight_19.csv.gz",
                                                                       1.1, 1.0, seed=2)),
        Verdict("refused", "refused", "Not judged: /data/bad.csv: accel: looks like g",
                file="/data/bad.csv", reason="/data/bad.csv: accel: looks like g"),
    )


@pytest.fixture
def result() -> Diagnosis:
    flights = _flights()
    refs = tuple(f"/data/nominal/flight_0{k}.csv.gz" for k in range(3))
    return Diagnosis(
        "quadsim.gap/3", "crazyflie21", "per-flight", flights=flights,
        answer=batch_answer(flights), reference=refs,
        reference_model={"params": {"motor_lag.time_constant": 0.0105, "wind.vx": -30.0},
                         "se": {"motor_lag.time_constant": 0.001, "wind.vx": 1e3},
                         "scatter": {"motor_lag.time_constant": 0.002, "wind.vx": 0.0},
                         "identified": {"motor_lag.time_constant": True, "wind.vx": False},
                         "sigma": dict(zip(CHANNELS, SIGMA)),
                         "delays_ms": {"gyro": {"mean": -5.7, "sd": 0.1, "count": 3}}},
        notes=("only 3 reference flights: their scatter is poorly known; give 10 or more",
               "/data/nominal/flight_00.csv.gz: signal delays vs motion capture: gyro -5.6 ms,"
               " rotor -9.8 ms (estimated; a gyro delay of 1.5 samples or more is shifted out"
               " before fitting, the others are reported only)",
               "/data/nominal/flight_01.csv.gz: accel: delay not resolvable from this log (the"
               " two halves give -13.6 and -59.1 ms, more than 4 ms apart: filtered or delayed"
               " beyond what its partner signal can time)"))


class _Page(HTMLParser):
    """Cells (class, text) of every table, in order, with the table's index; the svg
    count; every element id; the text outside tables, svg and the appendix."""

    def __init__(self):
        super().__init__()
        self.cells: list[tuple[int, str, str]] = []
        self.heads: list[list[str]] = []
        self.svgs, self.ids, self.text = 0, [], []
        self._cell, self._class, self._tables, self._depth = None, "", -1, 0
        self._skip = 0

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if "id" in attrs:
            self.ids.append(attrs["id"])
        if tag == "svg":
            self.svgs += 1
            self._skip += 1
        elif tag in ("details", "style"):
            self._skip += 1
        elif tag == "table":
            self._tables += 1
            self.heads.append([])
        elif tag in ("td", "th"):
            self._cell, self._class = "", attrs.get("class", "") if tag == "td" else "th"

    def handle_endtag(self, tag):
        if tag in ("svg", "details", "style"):
            self._skip -= 1
        elif tag in ("td", "th") and self._cell is not None:
            if self._class == "th":
                self.heads[-1].append(self._cell)
            else:
                self.cells.append((self._tables, self._class, self._cell))
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        elif not self._skip:
            self.text.append(data)


def _parse(text: str) -> _Page:
    parser = _Page()
    parser.feed(text)
    return parser


def test_the_figures_are_inline_svg_with_ids_of_their_own(result):
    text = page(result)
    parsed = _parse(text)
    # the batch figure, then per judged flight its residual against time and against
    # speed and thrust; no image file, no network
    assert parsed.svgs == 1 + 2 * 3
    assert "<img" not in text and 'src="http' not in text and "<script" not in text
    assert len(parsed.ids) == len(set(parsed.ids))
    # each flight's figures draw its series: against time, and its three largest channels
    # against speed and against thrust
    assert text.count("time (s)") == 3 and text.count("speed (m/s)") == 3 * 3
    assert text.count("collective thrust (N)") == 3 * 3


def test_every_table_cell_is_a_name_or_a_value_with_its_unit(result):
    parsed = _parse(page(result))
    assert parsed.cells
    for table, css, text in parsed.cells:
        if "name" in css.split():
            assert text.strip(), (table, text)
            continue
        if re.search(r"\d", text):
            assert UNIT.search(text), (table, css, text)
    names = [text for _, css, text in parsed.cells if "name" in css.split()]
    # flight names whole, in cells that do not wrap
    for f in ("flight_110.csv.gz", "flight_102.csv.gz", "flight_19.csv.gz", "bad.csv"):
        assert f in names
    assert "white-space:nowrap" in page(result)


def test_the_first_screen_answers_per_flight(result):
    parsed = _parse(page(result))
    first = [(css, text) for table, css, text in parsed.cells if table == 0]
    assert parsed.heads[0] == ["flight", "verdict", "leading reading (probability*)",
                               "what differs (95 % intervals)",
                               "residual before -> after the answer**", "excess removed",
                               "what remains***"]
    row = [text for _, text in first[:7]]
    # removed: 1 - (1.5^2 - 1) / (5 (2^2 - 1) + (4^2 - 1)) of the excess
    assert row == ["flight_110.csv.gz", "mass_offset", "mass_offset 93 %",
                   "+6.1 ± 0.3 g heavier (+16.5 % of the model's 37 g)",
                   "4x (Fz) -> 1.5x (Fz)", f"{100 * (1 - 1.25 / 30):.0f} %",
                   "nothing beyond the references"]
    # an unexplained flight: whose probability it is, what remains
    row = [text for _, text in first[7:14]]
    assert row[2] == "cable_payload > 99 %" and row[6] == "Fy 5.1x"
    assert row[4:6] == ["7x (Fy) -> 5.1x (Fy)",
                        f"{100 * (1 - (5.1 ** 2 - 1) / (9 * 35 + 48)):.0f} %"]
    top = "".join(parsed.text)
    assert "the references' typical RMS" in top and "Reference self-check" in top
    assert "3 flights judged against the reference flights" in top
    # the shared symptom of the two flights short of thrust: one row
    row = next(k for k, (_, _, text) in enumerate(parsed.cells) if text == "Fz -")
    assert [c for _, _, c in parsed.cells[row:row + 4]] == [
        "Fz -", "2 flights", "Fz -16.5 % of the weight .. -13.9 % of the weight",
        "mass_offset: flight_110.csv.gz; unexplained: flight_102.csv.gz"]


def test_every_reading_named_with_its_magnitude_and_delays_in_one_table(result):
    text = page(result)
    parsed = _parse(text)
    cells = [c for _, _, c in parsed.cells]
    assert "-14 ± 1 % thrust per Ω² on all 4 rotors" in cells and "thrust_factor" in cells
    assert "The two leading readings (mass_offset, thrust_factor) differ most on Fz, Mx." \
        in "".join(parsed.text)
    delays = next(h for h in parsed.heads if h[:2] == ["flight", "role"])
    assert delays == ["flight", "role", "accel (ms)", "gyro (ms)", "rotor (ms)"]
    assert "not resolvable" in cells and "-5.7 ± 0.1 ms" in cells
    outside = "".join(parsed.text)
    assert "signal delays vs motion capture:" not in outside    # not repeated in the notes
    # the reference model with a unit in every value; an undetermined value not printed
    assert "0.0105 s" in cells and "-30" not in " ".join(cells)


def test_the_same_words_in_the_page_and_the_json(result):
    text = page(result)
    for f in result.flights:
        assert f.answer.replace("'", "&#x27;") in text
        if f.series is not None:
            said = f.to_json()["residual"]["text"]
            assert said == residual_text(f.series.share(), f.outcome)
            assert said.replace("'", "&#x27;") in text


def test_the_share_removed_by_closed_form():
    share = _series("a", 3.0, 2.0).share()
    assert np.allclose(share.before, 3.0) and np.allclose(share.after, 2.0)
    assert share.removed == pytest.approx(1 - 3.0 / 8.0)      # (4 - 1) / (9 - 1) left
    assert _series("a", 0.9, 0.5).share().removed is None      # no excess: nothing to remove
    assert residual_text(_series("a", B110, A110).share(), "effect") == (
        "Residual up to 4x the references' RMS (Fz) before the answer, 1.5x (Fz) after it: "
        "it removes 96 % of the excess.")
    assert residual_text(_series("a", B110, A110).share(), "no_significant_gap") == (
        "Residual up to 4x the references' RMS (Fz).")


def test_a_page_from_json_read_back_has_no_figures_but_every_table(result):
    import json

    from quadsim.gap.report import to_json

    back = json.loads(to_json(result))
    text = page(back)
    assert "<svg" not in text and "flight_110.csv.gz" in text


def test_held_out_page_draws_the_held_out_flight():
    channels = {c: {"before": 3 * s, "after": s, "floor": s, "unit": u, "at_floor": True}
                for c, s, u in zip(CHANNELS[:6], SIGMA, ("N", "N", "N", "N m", "N m", "N m"))}
    verdict = Verdict("effect", "mass_offset", "Behaves as if +6 g heavier (> 99 %).", 1.0,
                      channels=channels)
    series = _series("/data/h.csv", 3.0, 1.0)
    result = Diagnosis("quadsim.gap/3", "crazyflie21", "held-out", verdict=verdict,
                       train=("a", "b"), holdout=("h",), series=series,
                       effects=({"name": "mass_offset", "probability": 1.0, "reduction": 0.9,
                                 "params": {"mass_offset.mass": 0.006},
                                 "ci": {"mass_offset.mass": 0.0004}},),
                       where={"kstep_before": {"0.1": {"position_rms_m": 0.02,
                                                       "attitude_rms_rad": 0.05}},
                              "kstep_after": {"0.1": {"position_rms_m": 0.01,
                                                      "attitude_rms_rad": 0.04}}})
    parsed = _parse(page(result))
    assert parsed.svgs == 3          # against time, against speed and thrust, k-step
    for _, css, text in parsed.cells:
        if "name" not in css.split() and re.search(r"\d", text):
            assert UNIT.search(text), text
    # two held-out flights: each drawn (2 figures each) and named, plus the k-step figure
    second = _series("/data/g.csv", 2.0, 1.0)
    both = dataclasses.replace(result, holdout=("h", "g"), held_series=(series, second))
    html = page(both)
    assert _parse(html).svgs == 5
    assert "Held-out flight h.csv" in html and "Held-out flight g.csv" in html


# --- the series of a judged flight -------------------------------------------------------

@pytest.fixture(scope="module")
def judged():
    """A flight 6 g heavier than three references that share a lag and rotor drag."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.core.errors import QuadsimWarning
    from quadsim.effects import make_effect
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare
    from quadsim.vehicle.params import load_params

    from _helpers import shared_effects

    cf = load_params("crazyflie21")
    logs = [synthetic_flight(cf, shared_effects(), duration=4.0, seed=s, speed=0.8 + 0.2 * s)
            for s in range(3)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        reference = calibrate(prepare(logs, cf), cf)
    heavy = synthetic_flight(cf, shared_effects() + [make_effect("mass_offset", mass=0.006)],
                             duration=4.0, seed=40, speed=1.0)
    return cf, judge_one(heavy, reference)


def test_the_series_shows_the_payload_before_and_not_after(judged):
    cf, verdict = judged
    assert verdict.name == "mass_offset", verdict.answer
    s = verdict.series
    assert s.before.shape == s.after.shape == (len(s.t), len(s.channels))
    fz = s.channels.index("Fz")
    # before: the model misses 6 g: Fz (the nominal mass times the measured specific force
    # T / (m + dm), less the thrust T) is -T dm / (m + dm), T = b sum Omega^2
    from quadsim.gap.page import thrust

    mean = float(np.mean(s.before[:, fz]))
    expected = float(np.mean(-thrust(s) * 0.006 / (cf.mass + 0.006)))
    assert mean == pytest.approx(expected, abs=0.5 * s.sigma[fz]), (mean, expected)
    # after: the answer takes it out; the residual at the references' level
    assert abs(float(np.mean(s.after[:, fz]))) < 0.2 * abs(expected)
    share = s.share()
    assert share.before[fz] > 5 and share.after[fz] < 2 and share.removed > 0.9


def test_the_recording_carries_the_same_series(result):
    from quadsim.gap.report import recording

    kw = recording(result)
    judged = [f for f in result.flights if f.series is not None]
    assert sorted(kw["trajectories"]) == sorted(Path(f.file).name for f in judged)
    assert len(kw["residuals"]) == 6 * len(judged)
    t, values, labels = kw["residuals"]["Fz flight_110.csv.gz"]
    series = judged[0].series
    assert labels == ["before", "after", "band +", "band -"]
    assert np.array_equal(values[:, 0], series.before[:, 2])
    assert np.array_equal(values[:, 1], series.after[:, 2])
    assert np.allclose(values[:, 2], 1.96 * SIGMA[2]) and np.allclose(values[:, 3],
                                                                      -1.96 * SIGMA[2])


@pytest.mark.skipif(__import__("shutil").which("chromium") is None,
                    reason="no Chromium on the PATH")
def test_the_page_renders_in_a_headless_browser(result, tmp_path):
    from benchmarks.report_screenshot import render

    html = tmp_path / "r.html"
    html.write_text(page(result), encoding="utf-8")
    png = render(html, tmp_path / "r.png", height=900).read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert (width, height) == (1400, 900)
