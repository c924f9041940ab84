"""``python -m benchmarks.gap_benchmark --per-flight-speed DATA`` prints the verdicts the
CLI gives (README: "the 26 mixed Crazyflie flights ... the CLI's verdicts"): its reference
stage must include the references' self-check, as ``quadsim.gap.diagnose.calibrated_stage``
does. Without it the printed verdicts were not the CLI's (no lack-of-fit scale: plain
flight 120 read ``thrust_mismatch``, the CLI ``unexplained``). Checked here on generated
flights laid out as the shared data: each printed line against ``diagnose_per_flight``, as
the CLI words it (the verdict said once: an effect's answer begins with its name)."""

from __future__ import annotations

import warnings

import pytest

from benchmarks.synthetic import synthetic_flight
from quadsim.core.errors import QuadsimWarning
from quadsim.effects import make_effect
from quadsim.gap import diagnose_per_flight
from quadsim.gap.report import flights_summary
from quadsim.logs.flightlog import load_log, write_log
from quadsim.vehicle.params import load_params


def test_per_flight_speed_prints_the_clis_verdicts(tmp_path):
    from benchmarks.gap_benchmark import per_flight_speed

    cf = load_params("crazyflie21")
    root = tmp_path / "crazyflie21_brushless"
    (root / "nominal").mkdir(parents=True)
    (root / "mixed").mkdir()
    for seed in (70, 71, 72, 73):
        write_log(root / "nominal" / f"flight_{seed}.csv.gz",
                  synthetic_flight(cf, [], duration=3.0, seed=seed))
    write_log(root / "mixed" / "flight_1.csv.gz",
              synthetic_flight(cf, [make_effect("mass_offset", mass=0.006)], duration=3.0,
                               seed=74))
    text = per_flight_speed(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        nominal = [load_log(p) for p in sorted((root / "nominal").glob("*.csv.gz"))]
        mixed = [load_log(root / "mixed" / "flight_1.csv.gz")]
    result = diagnose_per_flight(mixed, nominal, cf)
    flight = result["flights"][0]
    cli = [line.strip() for line in flights_summary(result).splitlines()
           if line.strip().startswith("flight_1.csv.gz: ")]     # the CLI's line, said once
    assert "reference calibration and self-check (4 flights)" in text
    assert len(cli) == 1 and cli[0] in text.splitlines()
    assert flight["verdict"] != "refused"


if __name__ == "__main__":
    pytest.main([__file__, "-q", "-n", "0"])
