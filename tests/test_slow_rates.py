"""A channel logged slower than the dynamics it must carry (issue 47): each channel's native
rate read from the data (:mod:`quadsim.logs.rates`) or given by the importer
(``FlightLog.rates_hz``), and the diagnosis' check on it (:func:`quadsim.gap.logcheck.
slow_rotors`): rotor speeds too slow for the moments are synthesised from fast commands
through a map fitted on them; with nothing fast carrying the rotors the flight is refused.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.synthetic import flyable_flight, synthetic_flight
from quadsim.core.errors import InputError
from quadsim.gap.logcheck import needed_rate_hz, slow_rotors, smoothing_cutoff_hz
from quadsim.logs.flightlog import load_log, log_bytes, write_log
from quadsim.logs.rates import native_rate
from quadsim.vehicle.params import load_params

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
RATE = 500.0


def _held(t: np.ndarray, x: np.ndarray, hz: float) -> np.ndarray:
    """``x`` (N, ...) sampled at ``hz`` on the rows nearest after t0 + k / hz, held."""
    rows = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], 1.0 / hz)))
    last = np.searchsorted(t[rows], t, side="right") - 1
    return x[rows[last]]


def _interpolated(t: np.ndarray, x: np.ndarray, instants: np.ndarray) -> np.ndarray:
    """``x`` (N,) sampled at ``instants`` (s; linear between rows) and interpolated back."""
    return np.interp(t, instants, np.interp(instants, t, x))


@pytest.fixture(scope="module")
def signal():
    t = np.arange(0.0, 10.0, 1.0 / RATE)
    rng = np.random.default_rng(0)
    x = 1500.0 + 80.0 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0.0, 3.0, len(t))
    return t, x


def test_held_channel_reads_its_sample_rate(signal):
    """4 Hz held on 500 Hz rows: a new value every 125 rows, 0.25 s: 4 Hz, "held"; its
    knots are the rows where the values change (exactly those sampled)."""
    t, x = signal
    rate = native_rate(t, _held(t, x, 4.0))
    assert rate.form == "held"
    assert rate.hz == pytest.approx(4.0, rel=1e-9)
    np.testing.assert_array_equal(rate.knots, np.arange(125, len(t), 125))


def test_interpolated_channel_reads_its_sample_rate(signal):
    """Linear interpolation between samples on the rows (10 Hz: every 50 rows): 10 Hz; between
    rows (7 Hz: every 71.43 rows, each sample bending the two rows around it): 7 Hz to one
    row in 71 (the median knot interval is 71 or 72 rows)."""
    t, x = signal
    on_rows = native_rate(t, _interpolated(t, x, t[::50]))
    assert (on_rows.form, on_rows.hz) == ("interpolated", pytest.approx(10.0, rel=1e-9))
    between = native_rate(t, _interpolated(t, x, np.arange(0.0003, t[-1], 1.0 / 7.0)))
    assert between.form == "interpolated"
    assert between.hz == pytest.approx(7.0, rel=1.0 / 71)


def test_interpolated_on_jittered_rows_reads_its_rate(signal):
    """Rows at 500 Hz with +-0.1 ms jitter (as the Crazyflie's), a channel sampled at 4 Hz on
    them and interpolated linearly in time: 4 Hz (a second difference in the row index would
    see the jitter times the slope on every row, and read native)."""
    t, x = signal
    t = t + np.random.default_rng(1).uniform(-1e-4, 1e-4, len(t))
    rows = np.arange(0, len(t), 125)
    rate = native_rate(t, np.interp(t, t[rows], x[rows]))
    assert rate.form == "interpolated"
    assert rate.hz == pytest.approx(4.0, rel=0.01)


def test_native_channel_reads_the_rows_rate(signal):
    """A noisy channel changes and bends on every row: native, 500 Hz; four columns of it
    (rotors) alike; a constant one reads nothing (None); a 250 Hz hold: every 2 rows."""
    t, x = signal
    rate = native_rate(t, x)
    assert (rate.form, rate.hz) == ("native", pytest.approx(RATE, rel=1e-6))
    assert native_rate(t, np.stack([x, x[::-1], x + 1, x * 2], 1)).form == "native"
    assert native_rate(t, np.full(len(t), 3.7)) is None
    assert native_rate(t, _held(t, x, 250.0)).hz == pytest.approx(250.0, rel=1e-6)


def test_quantised_column_reads_native(signal):
    """A 500 Hz battery voltage in 1 mV steps (4.2 V falling 0.15 V over 10 s: a step every
    ~33 rows, each one quantum): native, not held at its steps' 15 Hz; the 4 Hz-held signal
    rounded to 1 rad/s stays held (its changes are many steps, unequal); a smooth column
    without noise written in full (a generated command) bends on every row: native."""
    t, x = signal
    volts = np.round((4.2 - 0.015 * t) * 1000.0) / 1000.0
    assert native_rate(t, volts).form == "native"
    assert native_rate(t, np.round(_held(t, x, 4.0))).hz == pytest.approx(4.0, rel=1e-9)
    smooth = 0.42 + 0.01 * np.sin(2 * np.pi * 0.2 * t)
    assert native_rate(t, smooth).form == "native"


def test_smoothing_cutoff_and_need():
    """The -3 dB frequency of the 0.1 s cubic Savitzky-Golay at 100 Hz (11 taps), checked
    against its transfer function summed directly: gain 1/sqrt(2) there (to the grid's
    step), above it just below; the need is twice it, 19.75 Hz."""
    from scipy.signal import savgol_coeffs

    f = smoothing_cutoff_hz(0.1, 100.0)
    c = savgol_coeffs(11, 3)
    k = np.arange(11) - 5

    def gain(hz):
        return abs(np.sum(c * np.exp(-2j * np.pi * hz / 100.0 * k)))

    assert gain(f) == pytest.approx(1 / np.sqrt(2), abs=2e-3)
    assert gain(0.98 * f) > 1 / np.sqrt(2)
    assert needed_rate_hz() == pytest.approx(2 * f)
    assert 19.5 < needed_rate_hz() < 20.0


def test_csv_reads_a_held_rotor_column_back_at_its_rate(tmp_path, signal):
    """A 4 Hz-held rotor column in a 500 Hz CSV reads back as 4 Hz, the commands as 500 Hz;
    the file is what it was without the rates (convert writes nothing new)."""
    cf = load_params("crazyflie21")
    log = synthetic_flight(cf, duration=4.0, seed=1)
    slow = dataclasses.replace(log, rotor_speed=_held(log.t, log.rotor_speed, 4.0))
    path = write_log(tmp_path / "slow.csv", slow)
    back = load_log(path, warn=False)
    assert back.rate_hz("rotor_speed") == pytest.approx(4.0, rel=0.01)
    assert back.rate_hz("rotor_command") == pytest.approx(RATE, rel=1e-3)
    assert log_bytes(back, gzipped=False) == log_bytes(
        dataclasses.replace(back, rates_hz=()), gzipped=False)
    assert back.take(slice(0, 900)).rates_hz == back.rates_hz        # slicing carries them


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


def _slow_log(cf, tmp, name, seed, *, command_hz=None, speed=None, duration=6.0,
              speed_hz=4.0, effects=()):
    """An exact synthetic flight (``duration`` s, path ``speed``, default 0.8 + 0.1 seed, or
    slower where the rotors cannot fly it: :func:`benchmarks.synthetic.flyable_flight`; hidden
    ``effects``) with its rotor speeds held at ``speed_hz`` (commands at ``command_hz`` held
    too, else full rate), written and read back as a user's CSV."""
    log = flyable_flight(cf, effects, duration=duration, seed=seed,
                         speed=0.8 + 0.1 * seed if speed is None else speed)
    log = dataclasses.replace(log, rotor_speed=_held(log.t, log.rotor_speed, speed_hz))
    if command_hz:
        log = dataclasses.replace(log, rotor_command=_held(log.t, log.rotor_command, command_hz))
    return load_log(write_log(tmp / f"{name}.csv", log), warn=False)


def test_slow_speeds_are_synthesised_from_the_commands(cf, tmp_path):
    """Speeds held at 4 Hz: replaced by the commands through a map fitted at their 24 logged
    samples (its lag fitted there too: ~0.5 ms, the generated commands have none; the set's
    50 ms would leave 67 rad/s): within 1 % RMS of the true full-rate speeds (8.7 rad/s),
    where the held ones are 10x further off (153 rad/s); commands dropped; the correction
    says it."""
    true = synthetic_flight(cf, duration=6.0, seed=3, speed=1.1)
    slow = _slow_log(cf, tmp_path, "a", 3)
    out = slow_rotors(slow)
    assert out.speeds_synthesised and out.rotor_command is None
    assert out.corrections[-1].startswith("rotor speeds logged at 4 Hz, too slow for the "
                                          "moments (needs >= 19.8 Hz): speeds synthesised "
                                          "from the commands (500 Hz)")
    rms = float(np.sqrt(np.mean((out.rotor_speed - true.rotor_speed) ** 2)))
    held = float(np.sqrt(np.mean((slow.rotor_speed - true.rotor_speed) ** 2)))
    assert rms < 0.01 * float(np.mean(true.rotor_speed))
    assert held > 10 * rms
    assert "tau 0." in out.notes[-1]                                  # < 1 ms
    assert slow_rotors(out) is out                                 # done once
    native = load_log(write_log(tmp_path / "n.csv", true), warn=False)
    assert slow_rotors(native) is native                           # native: as is


def test_nothing_fast_carrying_the_rotors_is_refused(cf, tmp_path):
    """Speeds at 4 Hz and commands at 10 Hz; or commands alone at 10 Hz: one line naming the
    file, the channel and the rates."""
    both = _slow_log(cf, tmp_path, "b", 4, command_hz=10.0)
    with pytest.raises(InputError, match=r"b\.csv: rotor_1..rotor_N: rotor speeds logged at "
                       r"4 Hz and motor commands at 10 Hz: too slow for the moments \(needs "
                       r">= 19.8 Hz"):
        slow_rotors(both)
    alone = dataclasses.replace(both, rotor_speed=None)
    with pytest.raises(InputError, match=r"cmd_1..cmd_N: motor commands logged at 10 Hz and "
                       "no rotor speeds: too slow"):
        slow_rotors(alone)


def test_gap_judges_slow_speeds_through_the_commands(cf, tmp_path):
    """Per flight, two nominal generated flights (8 s, path speeds 0.95 and 1.25) against 10
    references (0.7-1.6), every one's rotor speeds held at 4 Hz, commands at 500 Hz:
    no_significant_gap, the correction in the answer. Before (main 457c8f3, the same
    flights): ``signal_delay`` 63 % and 99 % ("the rotor speeds are timed 38 / 44 ms later":
    the hold's lag); at full rate both clear. (A flight with its commands held at 10 Hz too
    sets the run's band: :func:`test_gap_judges_slow_rotors_in_their_band`.)"""
    from quadsim.gap.__main__ import main

    refs = [str(_slow_log(cf, tmp_path, f"ref{s}", s, speed=0.7 + 0.1 * s, duration=8.0).path)
            for s in range(10)]
    judged = [str(_slow_log(cf, tmp_path, f"judged{s}", s, speed=0.8 + 0.15 * (s - 20),
                            duration=8.0).path) for s in (21, 23)]
    out = tmp_path / "out.json"
    main(["--model", "crazyflie21", "--per-flight", *judged, "--reference", *refs,
          "--workers", "1", "--quiet", "--json", str(out),
          "--cache-dir", str(tmp_path / "cache")])
    flights = {Path(f["file"]).stem: f for f in json.loads(out.read_text())["flights"]}
    for name in ("judged21", "judged23"):
        assert flights[name]["verdict"] == "no_significant_gap", flights[name]["answer"]
        assert "rotor speeds logged at 4 Hz, too slow for the moments" in flights[name]["answer"]
        assert "judged below" not in flights[name]["answer"]


def test_band_window_and_timing():
    """The band's window: the shortest on the 0.01 s grid whose cubic Savitzky-Golay -3 dB
    frequency at 100 Hz is at most a quarter of the rate (closed form of the gain: scipy's
    ``savgol_coeffs`` through ``freqz``, independently of the module's search): 0.42 s for
    10 Hz (2.48 Hz; 0.41 s would be 2.54 Hz), 0.86 s for 5 Hz; timing readings carried at
    windows up to 0.2 s (5.10 Hz >= 19.75 / 4), not at 0.22 s (4.65 Hz)."""
    from scipy.signal import freqz, savgol_coeffs

    from quadsim.gap.logcheck import band_window_s, timing_carried

    def edge(window):
        n = int(round(window * 100.0)) | 1
        f, g = freqz(savgol_coeffs(n, 3), worN=4096, fs=100.0)
        return f[np.flatnonzero(np.abs(g) < 2 ** -0.5)[0]]

    for hz, window in ((10.0, 0.42), (5.0, 0.86)):
        assert band_window_s(hz) == pytest.approx(window)
        assert edge(window) <= hz / 4 < edge(window - 0.01)
    assert timing_carried(0.1) and timing_carried(0.2) and not timing_carried(0.22)


def test_rejoined_draws_a_held_channel_through_its_samples():
    """A 10 Hz hold of a 0.7 Hz sine lags it by half an interval: drawn again through its
    samples (the rows where a new value shows) it lies within the linear interpolation's
    error of the sine, (pi f / r)^2 / 2 of its amplitude = 0.24 % (the held one is off by
    up to 2 pi f / (2 r) ... 2 pi f / r of it: 22-44 %); an interpolated channel is left."""
    from quadsim.gap.logcheck import rejoined
    from quadsim.logs.flightlog import FlightLog

    t = np.arange(0.0, 8.0, 1.0 / RATE)
    x = 1500.0 + 100.0 * np.sin(2 * np.pi * 0.7 * t)
    rotors = np.stack([x, x + 10, x + 20, x + 30], axis=1)
    held = _held(t, rotors, 10.0)
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(t), 1))
    log = FlightLog(t, np.zeros((len(t), 3)), quat, rotor_speed=held,
                    rates_hz=(("rotor_speed", 10.0),))
    out = rejoined(log)
    inner = (t > 0.2) & (t < 7.8)
    err = np.max(np.abs(out.rotor_speed - rotors)[inner]) / 100.0
    assert err < (np.pi * 0.7 / 10.0) ** 2 / 2 * 1.05 + 1.0 / RATE * 2 * np.pi * 0.7
    assert np.max(np.abs(held - rotors)[inner]) / 100.0 > 0.2
    lined = dataclasses.replace(log, rotor_speed=out.rotor_speed)
    assert rejoined(lined) is lined


def test_gap_judges_slow_rotors_in_their_band(cf, tmp_path):
    """Rotor speeds and commands both held at 10 Hz (ArduPilot's RCOU) in flights and
    references alike (10 generated references, path speeds 0.7-1.6): main refused every
    flight ("too slow for the moments"); judged in the band, a flight 20 % heavier
    (mass_offset +7.4 g of 37 g) is named mass_offset within 10 % of its mass, a flight
    without an effect is clear, and the answers state the band."""
    from quadsim.effects import make_effect
    from quadsim.gap.__main__ import main

    kw = dict(duration=8.0, speed_hz=10.0, command_hz=10.0)
    refs = [str(_slow_log(cf, tmp_path, f"ref{s}", s, speed=0.7 + 0.1 * s, **kw).path)
            for s in range(10)]
    extra = 0.2 * cf.mass
    heavy = _slow_log(cf, tmp_path, "heavy", 21, speed=0.95,
                      effects=(make_effect("mass_offset", mass=extra),), **kw)
    plain = _slow_log(cf, tmp_path, "plain", 23, speed=1.1, **kw)
    out = tmp_path / "out.json"
    main(["--model", "crazyflie21", "--per-flight", str(heavy.path), str(plain.path),
          "--reference", *refs, "--workers", "1", "--quiet", "--json", str(out),
          "--cache-dir", str(tmp_path / "cache")])
    flights = {Path(f["file"]).stem: f for f in json.loads(out.read_text())["flights"]}
    assert flights["plain"]["verdict"] == "no_significant_gap", flights["plain"]["answer"]
    assert flights["heavy"]["verdict"].startswith("mass_offset"), flights["heavy"]["answer"]
    share = re.search(r"\+([0-9.]+) % of the model's", flights["heavy"]["answer"])
    assert float(share.group(1)) == pytest.approx(20.0, rel=0.1)        # +20.5 % measured
    for f in flights.values():
        assert "judged below 2.5 Hz: rotor speeds logged at 10 Hz" in f["answer"]


def test_command_only_flight_against_slow_references_is_refused(cf, tmp_path, capsys):
    """A command-only flight against references whose speeds are too slow (synthesised from
    their commands, which are then dropped): refused in one line, exit 2 (before: "no
    commands to synthesise rotor speeds from", naming a reference)."""
    from quadsim.gap.__main__ import main

    refs = [str(_slow_log(cf, tmp_path, f"r{s}", s).path) for s in range(2)]
    log = synthetic_flight(cf, duration=6.0, seed=5)
    only = write_log(tmp_path / "only.csv", dataclasses.replace(log, rotor_speed=None))
    assert main(["--model", "crazyflie21", "--per-flight", str(only), "--reference", *refs,
                 "--workers", "1", "--quiet", "--cache-dir", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "r0.csv: rotor_1..rotor_N: the reference flights' rotor speeds are logged too " \
           "slowly" in err


def test_a_run_too_slow_even_for_a_band_is_one_line_and_nothing_written(cf, tmp_path, capsys):
    """Rotor speeds and commands both held at 4 Hz (below MIN_BAND_RATE_HZ = 5 Hz): the run
    is refused through the CLI in one line naming the file and the rates, exit 2, no JSON
    written."""
    from quadsim.gap.__main__ import main

    refs = [str(_slow_log(cf, tmp_path, f"s{s}", s, command_hz=4.0).path) for s in range(3)]
    flight = _slow_log(cf, tmp_path, "f", 5, command_hz=4.0)
    out = tmp_path / "out.json"
    assert main(["--model", "crazyflie21", "--per-flight", str(flight.path), "--reference",
                 *refs, "--workers", "1", "--quiet", "--json", str(out),
                 "--cache-dir", str(tmp_path / "c")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "too slow even for a band (needs >= 5 Hz" in err[0], err
    assert "rotor speeds logged at 4" in err[0] and "Traceback" not in err[0]
    assert not out.exists()


@pytest.mark.skipif(not (DATA / "px4_ulog").is_dir(), reason="shared data absent")
def test_importers_state_their_topics_rates():
    """The PX4 sample: esc_status at 4.03 Hz, actuator_motors at 10 Hz, sensor_combined at
    250 Hz (each topic's median interval); the ArduPilot log's RCOU at 10 Hz."""
    px4 = load_log(DATA / "px4_ulog" / "sample_px4_events.ulg", warn=False)
    rates = dict(px4.rates_hz)
    assert rates["rotor_speed"] == pytest.approx(4.03, abs=0.01)
    assert rates["rotor_command"] == pytest.approx(10.0, abs=0.01)
    assert rates["body_rate"] == pytest.approx(250.0, rel=0.01)
    ardu = load_log(DATA / "ardupilot_dataflash" / "copter_112.BIN", warn=False)
    assert dict(ardu.rates_hz)["rotor_command"] == pytest.approx(10.0, abs=0.01)


@pytest.mark.skipif(not (DATA / "crazyflie21_brushless").is_dir(), reason="shared data absent")
def test_crazyflie_speeds_and_commands_read_native():
    """Every shared Crazyflie flight's rotor speeds and commands read native at its ~500 Hz
    rows (the landing rule: unchanged logs do not move)."""
    for path in sorted((DATA / "crazyflie21_brushless").glob("*/flight_*.csv.gz")):
        log = load_log(path, warn=False)
        for channel in ("rotor_speed", "rotor_command"):
            assert log.rate_hz(channel) > 450.0, (path.name, channel)


def test_where_lists_only_the_bands_that_were_compared():
    """A residual sampled at 100 Hz with its power in a 3 Hz sine: all of it in "1-5 Hz";
    below a top of 2.48 Hz (the band of rotors logged at 10 Hz) the bands above are left
    out instead of reading 0 %, and the shares still add to 1."""
    from quadsim.gap.judge import by_band

    t = np.arange(0.0, 8.0, 0.01)
    e = np.column_stack([np.sin(2 * np.pi * 3.0 * t), 0.5 * np.sin(2 * np.pi * 3.0 * t)])
    whole = by_band([e], 0.01)
    assert list(whole) == ["0-1 Hz", "1-5 Hz", "5-20 Hz", "20-inf Hz"]
    assert whole["1-5 Hz"] == pytest.approx(1.0, abs=0.01)
    banded = by_band([e], 0.01, 2.48)
    assert list(banded) == ["0-1 Hz", "1-5 Hz"]
    assert sum(banded.values()) == pytest.approx(1.0, abs=1e-12)


def _smooth_speeds_log(tmp_path, path: str, seed: int, speed: float):
    """A generated 15 s flight of ``px4_sitl_iris`` at 100 Hz (rotor drag, body drag, a 30 ms
    motor lag: the xquad campaign's, ``benchmarks.campaigns``) whose rotor speeds carry no
    noise, written as a CSV (10 digits) and read back."""
    from quadsim.effects import EffectSet, make_effect
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel

    effects = EffectSet((make_effect("rotor_drag", coefficient=1e-5),
                         make_effect("motor_lag", time_constant=0.03),
                         make_effect("body_drag", cd_area=0.005, cd_area_vertical=0.01)))
    sensors = SensorModel(noise={"gyro": 0.01, "accel": 0.05, "rotor": 0.0,
                                 "position": 0.001}, rate=100.0)
    log, _ = generate_flight(load_params("px4_sitl_iris"), path, effects, sensors, seed,
                             duration=15.0, speed=speed, height=2.0, size=2.0)
    out = tmp_path / f"{path}{seed}.csv.gz"
    write_log(out, log)
    return load_log(out)


@pytest.mark.parametrize("path, seed, speed, before", [("lissajous", 1, 0.84, "25 Hz"),
                                                       ("steps", 2, 0.5, "20 Hz held"),
                                                       ("lissajous", 4, 0.96, "5 Hz")])
def test_smooth_channel_without_noise_reads_native(tmp_path, path, seed, speed, before):
    """Rotor speeds without noise (module doc, "dense" and "smooth"): on a lissajous they bend
    beyond the 10 digits' rounding only where the vehicle turns fast (12-20 rows in 15 s, at
    intervals of 2-376 rows, with 3-6 rows just under the threshold for each); in steps
    they stay on one written value at the steady hover and change on every row between.
    Native, 100 Hz, and the diagnosis keeps the logged speeds (``before``: the rate read
    then; the speeds were synthesised from the commands and a reference refused by the
    rotor-order check at Delta chi^2 35)."""
    log = _smooth_speeds_log(tmp_path, path, seed, speed)
    rate = native_rate(log.t, log.rotor_speed)
    assert (rate.form, rate.hz) == ("native", pytest.approx(100.0, rel=1e-6)), before
    assert slow_rotors(log) is log


@pytest.mark.skipif(not DATA.exists(), reason="needs ../shared/data")
def test_motion_capture_pose_stays_held():
    """The real Crazyflie flights' pose, held on the 500 Hz rows between motion-capture
    samples (a new value every 2-5 rows, each on a single row), still reads held at 104-175 Hz
    (docs/logs.md), not native."""
    for name in ("mixed/flight_100.csv.gz", "nominal/flight_00.csv.gz"):
        log = load_log(DATA / "crazyflie21_brushless" / name, warn=False)
        for channel in ("position", "quat"):
            assert 100.0 < log.rate_hz(channel) < 180.0, (name, channel)


def test_held_channel_constant_in_between_keeps_its_rate(signal):
    """A 4 Hz hold that stays on one value for 3 s in the middle (on the ground between two
    take-offs): its samples still tile the time it moves, 4 Hz "held"."""
    t, x = signal
    held = _held(t, x, 4.0)
    ground = (t > 3.0) & (t < 6.0)
    held[ground] = held[np.flatnonzero(ground)[0]]
    rate = native_rate(t, held)
    assert (rate.form, rate.hz) == ("held", pytest.approx(4.0, rel=1e-9))
