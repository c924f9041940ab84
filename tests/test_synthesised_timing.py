"""A rotor timing read on a log whose rotor speeds are synthesised from its commands is said
to be the commands' timing, not a logged signal's (``FlightLog.speeds_synthesised``,
``quadsim.gap.logcheck.synthesised_timing_note``, ``quadsim.logs.delays.delay_notes``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from quadsim.gap.logcheck import (
    SYNTHESISED_TIMING_WORDS,
    command_model_from_params,
    synthesise_speeds,
    synthesised_timing_note,
    without_speeds,
)
from quadsim.gap.result import Verdict
from quadsim.gap.words import TIMING_WORDS, reading_text
from quadsim.logs.delays import delay_notes
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import load_params


def _command_log(n: int = 400) -> FlightLog:
    """A 2 s IMU + commands log at 200 Hz (hover commands, a 3.7 V battery)."""
    t = np.arange(n) / 200.0
    command = np.full((n, 4), 0.45) + 0.02 * np.sin(2 * np.pi * 2 * t)[:, None]
    return FlightLog(t=t, position=None, quat=None, body_rate=np.zeros((n, 3)),
                     accel=np.tile([0.0, 0.0, 9.81], (n, 1)), rotor_command=command,
                     vbat=np.full(n, 3.7))


def test_synthesised_speeds_are_marked_and_follow_the_map():
    """``synthesise_speeds`` marks the log and its speeds are the set's map at the logged
    voltage through its lag (steady state: the map itself); a log cut to commands is not
    marked."""
    params = load_params("crazyflie21")
    log = _command_log()
    assert not log.speeds_synthesised
    out = synthesise_speeds(log, command_model_from_params(params))
    assert out.speeds_synthesised and out.rotor_command is None
    mm = params.motor_map
    # the last sample, ~4 time constants after the start, is within 2 % of the steady map
    steady = np.array([np.interp(log.rotor_command[-1, i], mm.command, mm.speed[i])
                       for i in range(4)])
    steady *= 1.0 + mm.voltage_gain * (3.7 - mm.reference_voltage)
    np.testing.assert_allclose(out.rotor_speed[-1], steady, rtol=0.02)
    assert not without_speeds(out).speeds_synthesised      # no speeds: nothing synthesised


def test_a_timing_answer_on_synthesised_speeds_says_what_it_times():
    """The note is added where a log's speeds are synthesised and the answer states the
    rotor timing reading, nowhere else; the outcome, name and numbers stay."""
    reference = SimpleNamespace(rotor_shift_s=-0.0063, params=load_params("crazyflie21"))
    ev = SimpleNamespace(name="signal_delay", determined={"delay.rotor": True},
                         values={"delay.rotor": 0.013}, post_sd={"delay.rotor": 0.0005})
    text = reading_text(ev, reference)
    assert text == ("the rotor speeds are timed 13 ± 1 ms later than on the reference "
                    "flights (references: -6.3 ms against the logged motion, fitted)")
    assert text.startswith(f"the {TIMING_WORDS}")
    named = Verdict("effect", "signal_delay", f"signal_delay (98 %): {text}.", 0.98)
    other = Verdict("effect", "mass_offset", "mass_offset (90 %): +4 g heavier.", 0.9)
    synth, logged = SimpleNamespace(speeds_synthesised=True), SimpleNamespace()
    noted = synthesised_timing_note(named, [logged, synth])
    assert noted.answer == f"{named.answer} {SYNTHESISED_TIMING_WORDS}"
    assert (noted.outcome, noted.name, noted.probability) == ("effect", "signal_delay", 0.98)
    assert synthesised_timing_note(named, [logged]) is named
    assert synthesised_timing_note(other, [synth]) is other


def test_delay_notes_name_a_synthesised_rotor_delay():
    flights = [SimpleNamespace(name="a.csv", delays_ms={"gyro": -3.4, "rotor": -5.8},
                               delay_notes=(), speeds_synthesised=True),
               SimpleNamespace(name="b.csv", delays_ms={"gyro": -3.4, "rotor": -5.8},
                               delay_notes=())]
    a, b = delay_notes(flights)
    assert "gyro -3.4 ms, rotor (synthesised from the commands) -5.8 ms" in a
    assert "gyro -3.4 ms, rotor -5.8 ms" in b
