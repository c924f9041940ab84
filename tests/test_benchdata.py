"""Transcribed report tables (spot checks against report cells and the report's own averages)
and bad-input handling of the bench-data loaders."""

import math

import numpy as np
import pytest

from quadsim.core.errors import InputError
from quadsim.identify.benchdata import (
    load_cfd_table,
    load_force_lift,
    load_physical_measurements,
    load_testbed_constants,
    load_thrust_stand,
)
from quadsim.identify.bifilar import load_bifilar_table

RPM = 2 * math.pi / 60


def test_force_lift_cells_match_report():
    lift = load_force_lift()
    command = list(lift.command)
    assert command == [40, 50, 60, 70, 80, 90, 100, 110, 120, 130, 140]
    k100, k140 = command.index(100), command.index(140)
    # Table 4.5 (motor 1), PWM 100: masses 0.340 0.339 0.341 kg, speeds 5259 5268 5253 RPM
    assert lift.thrust[0, :, k100] == pytest.approx(np.array([0.340, 0.339, 0.341]) * 9.81)
    assert lift.speed[0, :, k100] == pytest.approx(np.array([5259, 5268, 5253]) * RPM)
    # Table 4.7 (motor 2), PWM 140, trial 1: 0.510 kg, 7042 RPM
    assert lift.thrust[1, 0, k140] == pytest.approx(0.510 * 9.81)
    assert lift.speed[1, 0, k140] == pytest.approx(7042 * RPM)
    # Table 4.11 (motor 4), PWM 50, trial 3: 0.062 kg, 1520 RPM
    assert lift.thrust[3, 2, 1] == pytest.approx(0.062 * 9.81)
    assert lift.speed[3, 2, 1] == pytest.approx(1520 * RPM)


def test_force_lift_trials_reproduce_report_averages():
    # the report's Force column is the rounded mean mass x 9.81 (rounding <= 0.0005 kg),
    # its Angular Velocity column the rounded mean RPM in rad/s (rounding <= 0.5 RPM)
    lift = load_force_lift()
    assert np.max(np.abs(lift.thrust.mean(axis=1) - lift.published_force)) < 0.0005 * 9.81 + 1e-3
    assert np.max(np.abs(lift.speed.mean(axis=1) - lift.published_speed)) < 0.5 * RPM + 1e-3


def test_cfd_physical_bifilar_cells_match_report():
    cfd = load_cfd_table()
    assert cfd.thrust[list(cfd.command).index(110)] == pytest.approx(3.079)
    assert cfd.speed[-1] == pytest.approx(7057 * RPM)
    physical = load_physical_measurements()
    # Table 4.4 Average column
    for column, average in [("total_mass", 0.837667), ("base_mass", 0.346333),
                            ("frame_length", 0.191333), ("motor_to_centre", 0.197667),
                            ("motor_to_motor", 0.397333), ("base_radius", 0.067667)]:
        assert np.mean(physical[column]) == pytest.approx(average, abs=1e-6), column
    table = load_bifilar_table()
    assert table.periods["yaw"] == pytest.approx([4.16, 4.11, 4.02])
    assert table.periods["pitch"] == pytest.approx([0.44, 0.38, 0.41])
    rig = table.rig
    assert (rig.mass, rig.wire_half_spacing, rig.wire_length) == (0.838, 0.12, 0.4)
    assert load_testbed_constants()["propeller_diameter"][0] == pytest.approx(0.254)


GOOD_HEADER = "pwm[pwm],mass_1[kg],mass_2[kg],mass_3[kg],speed_1[rpm],speed_2[rpm],speed_3[rpm]"
GOOD_ROWS = ["50,0.06,0.06,0.06,1500,1500,1500", "100,0.34,0.34,0.34,5260,5260,5260",
             "140,0.54,0.54,0.54,7060,7060,7060"]


def _write(tmp_path, header, rows, name="lift.csv"):
    path = tmp_path / name
    path.write_text("# source: test\n" + "\n".join([header, *rows]) + "\n")
    return path


@pytest.mark.parametrize("header,rows,column,message", [
    (GOOD_HEADER + ",colour[-]", [r + ",1" for r in GOOD_ROWS], "colour", "unknown column"),
    (GOOD_HEADER.replace(",speed_3[rpm]", ""), [r.rsplit(",", 1)[0] for r in GOOD_ROWS],
     "speed_3", "missing column"),
    (GOOD_HEADER.replace("mass_2[kg]", "mass_2"), GOOD_ROWS, "mass_2", "no unit"),
    (GOOD_HEADER.replace("speed_1[rpm]", "speed_1[rad/s]"), GOOD_ROWS, "speed_1",
     "RPM given as rad/s"),
    (GOOD_HEADER.replace("mass_1[kg]", "mass_1[g]"), GOOD_ROWS, None, None),
    (GOOD_HEADER, [GOOD_ROWS[0], "100,0.34,nan,0.34,5260,5260,5260", GOOD_ROWS[2]], "mass_2",
     "NaN"),
    (GOOD_HEADER, [GOOD_ROWS[0], "100,0.34,,0.34,5260,5260,5260", GOOD_ROWS[2]], "mass_2", "NaN"),
    (GOOD_HEADER, [GOOD_ROWS[0], "100,0.34,abc,0.34,5260,5260,5260", GOOD_ROWS[2]], "mass_2",
     "not a number"),
    (GOOD_HEADER.replace("mass_3[kg]", "mass_3[N]"), GOOD_ROWS, "mass_3", "does not fit"),
    (GOOD_HEADER, [GOOD_ROWS[0], GOOD_ROWS[1].replace("0.34,0.34,0.34", "340,340,340")], "mass_1",
     "grams given as kg"),
    (GOOD_HEADER, GOOD_ROWS[:1], "pwm", "at least 2"),
])
def test_bad_force_lift_input_is_one_line_naming_file_and_column(tmp_path, header, rows,
                                                                  column, message):
    path = _write(tmp_path, header, rows)
    if column is None:  # grams are accepted and converted
        lift = load_force_lift([path])
        assert lift.thrust[0, 0, 0] == pytest.approx(0.06e-3 * 9.81)
        return
    with pytest.raises(InputError) as info:
        load_force_lift([path])
    text = str(info.value)
    assert "\n" not in text and str(path) in text and column in text and message in text


def test_too_few_running_points_for_the_fit(tmp_path):
    from quadsim.identify import fit_curve

    with pytest.raises(InputError, match="2 points with a running rotor, more than 2 needed"):
        fit_curve([0.0, 100.0, 200.0], [0.0, 0.1, 0.4], "quadratic+linear", where="x.csv")


def test_thrust_stand_header_units(tmp_path):
    path = tmp_path / "stand.csv"
    path.write_text("esc_us,torque_Nm,thrust_N,speed_rpm\n1100,0,0,0\n1500,0.02,1.5,4000\n"
                    "1800,0.05,3.5,6000\n")
    sweep = load_thrust_stand(path)
    assert sweep.speed[-1] == pytest.approx(6000 * RPM)
    path.write_text("esc_us,torque_Nm,thrust_N,speed\n1100,0,0,0\n1500,0.02,1.5,4000\n"
                    "1800,0.05,3.5,6000\n")
    with pytest.raises(InputError, match=r"stand\.csv: speed: no unit"):
        load_thrust_stand(path)
