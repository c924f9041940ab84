"""Helpers shared by several test files (not a test module)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from quadsim.effects import make_effect

ROOT = Path(__file__).resolve().parents[1]

#: what the generated reference flights of the per-flight tests share: an 8 ms motor lag (s)
#: and rotor drag (kg/rad)
LAG, DRAG = 0.008, 2e-7


def shared_effects(lag: float = LAG, drag: float = DRAG) -> list:
    """The effects every generated reference flight shares (motor lag, rotor drag)."""
    return [make_effect("motor_lag", time_constant=lag),
            make_effect("rotor_drag", coefficient=drag)]


def one_line(capsys, *names: str) -> str:
    """The captured refusal: nothing on stdout, one ``error:`` line naming ``names``."""
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert captured.out == "" and len(err.splitlines()) == 1, err
    assert err.startswith("error: "), err
    for name in names:
        assert name in err, err
    return err


def load_script(name: str):
    """The module of ``scripts/NAME.py`` (an analysis script, not a package module), loaded
    from this checkout and registered under ``name`` (its dataclasses look their module up)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


#: the sensor noise of the generated per-flight payload and reach tests (motion capture,
#: IMU, rotor speeds; SI units: m, m/s, rad, rad/s, m/s^2, rad/s)
MOCAP_NOISE = {"position": 5e-4, "velocity": 0.01, "attitude": 2e-3, "gyro": 0.02,
               "accel": 0.1, "rotor": 10.0}


def generated_flight(params, effects, seed: int, path: str, speed: float, *,
                     duration: float = 4.0):
    """One generated flight log of ``params`` with ``effects`` (a list of effect
    instances) on ``path`` at ``speed`` (m/s) under :data:`MOCAP_NOISE`
    (:func:`quadsim.logs.generate.generate_flight`; ``duration`` in s)."""
    from quadsim.effects import EffectSet
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel

    return generate_flight(params, path, EffectSet(tuple(effects)),
                           SensorModel(noise=MOCAP_NOISE), seed, duration=duration,
                           speed=speed)[0]


def fake_reach(allowance, counts=None, typical: float = 1.0, channels: int = 3):
    """A stand-in for :class:`quadsim.gap.reference.Reach` with what the judge's share and
    bias rules read: per channel the references' typical mean square ``typical``, the
    ``allowance`` (sigma^2 units) and the flight's effective samples ``counts`` (None: not
    kept); ``excess`` 1 (beyond the reach)."""
    from types import SimpleNamespace

    import numpy as np

    return SimpleNamespace(typical=np.full(channels, typical),
                           allowance=np.asarray(allowance, float),
                           counts=None if counts is None else np.asarray(counts, float),
                           excess=1.0)


def drag_flights(folder: Path) -> list[Path]:
    """Three short synthetic crazyflie21 flights with a rotor drag of 1e-6 kg/rad, seeds 60-62,
    4 s each, written into ``folder`` as f0..f2.csv.gz (two references and one judged, for the
    references' cache and the stored reference tests)."""
    from benchmarks.synthetic import synthetic_flight
    from quadsim.logs.flightlog import write_log
    from quadsim.vehicle.params import load_params

    cf = load_params("crazyflie21")
    drag = [make_effect("rotor_drag", coefficient=1e-6)]
    paths = []
    for k, seed in enumerate((60, 61, 62)):
        paths.append(folder / f"f{k}.csv.gz")
        write_log(paths[-1], synthetic_flight(cf, drag, seed=seed, duration=4.0))
    return paths


def commands_through_map(log, params):
    """:func:`benchmarks.synthetic.commands_through_map` (kept here under its name for the
    tests that import it from this module)."""
    from benchmarks.synthetic import commands_through_map as through_map

    return through_map(log, params)


def early_and_full(flights, params) -> tuple[float, float | None]:
    """The shared thrust-curve slope's spread over its threshold (``DETERMINED`` times its
    prior's) on the prepared reference ``flights``, read two ways: at the bounded fit
    without the slope (``calibrate._slope_spread``, what the calibration decides by) and
    after the whole calibration with the slope (``s_ref``; None where the fit with the slope
    already leaves it undetermined, ``calibrate._calibrated``)."""
    from quadsim.gap import calibrate as cal

    setup = cal._setup(flights, params)
    plain = cal.Candidate(setup.cand.name, tuple(p for p in setup.cand.parts
                                                 if p[0] != "thrust_curve"), setup.cand.base)
    limit = cal.DETERMINED * cal.curve_slope_sd(setup.params)
    early, _ = cal._slope_spread(setup, cal._bounded_fit(setup, plain))
    ref = cal._calibrated(setup, setup.cand, cal._bounded_fit(setup, setup.cand))
    if ref is None:
        return early / limit, None
    k = list(ref.candidate.parameter_names).index(cal.CURVE_KEY)
    return early / limit, float(ref.s_ref[k]) / limit


def crazyflie_without_lag():
    """The crazyflie21 set with its motor map's time constant 0: the generated flights'
    rotors follow their commands at once (the engines read a rotor lag only as the
    ``motor_lag`` effect), so their speeds are synthesised without the set's motor lag."""
    import dataclasses

    from quadsim.vehicle.params import load_params

    params = load_params("crazyflie21")
    return params.replace(motor_map=dataclasses.replace(params.motor_map, time_constant=0.0))


def commands_only_flight(params, effects, sensors, seed: int, path: str = "figure8", *,
                         duration: float, through_map: bool = False):
    """A generated closed-loop flight of ``params`` with ``effects`` (MuJoCo, ``sensors``,
    1 m/s, ``duration`` s) as a log with motor commands and no rotor speeds, checked
    (:func:`quadsim.logs.checks.check_logs`, QuadsimWarnings silenced); ``through_map``: its
    commands written again through the set's map (:func:`commands_through_map`)."""
    import dataclasses
    import warnings

    from quadsim.core.errors import QuadsimWarning
    from quadsim.effects import EffectSet
    from quadsim.logs.checks import check_logs
    from quadsim.logs.generate import generate_flight

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        log, _ = generate_flight(params, path, EffectSet(tuple(effects)), sensors, seed,
                                 duration=duration, speed=1.0)
        if through_map:
            log = commands_through_map(log, params)     # commands as the set's map has them
        return check_logs([dataclasses.replace(log, rotor_speed=None)], params)[0][0]


def judge_commands_only(params, references: list, flights: dict) -> dict:
    """The per-flight verdicts of command-only ``flights`` (name -> log) against command-only
    ``references`` (logs), their speeds synthesised from the commands
    (:func:`quadsim.gap.logcheck.synthesise_all`), QuadsimWarnings silenced: name -> verdict,
    and ``"model"`` (the command model), ``"reference"`` (the calibrated reference model),
    ``"prepared"`` (the prepared references)."""
    import warnings

    from quadsim.core.errors import QuadsimWarning
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare
    from quadsim.gap.logcheck import synthesise_all

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        roles, model = synthesise_all({"reference": references, "f": list(flights.values())},
                                      params)
        prepared = prepare(roles["reference"], params)
        reference = calibrate(prepared, params)
        out = {k: judge_one(log, reference) for k, log in zip(flights, roles["f"])}
    return out | {"model": model, "reference": reference, "prepared": prepared}


def lagging_flight(model: str, drag: float, lag: float, noise: dict, rate: float, seed: int,
                   path: str, *, duration: float, speed: float, height: float, size: float):
    """(params, log): a generated closed-loop flight of parameter set ``model`` with a rotor
    drag ``drag`` (kg/rad) and a motor lag ``lag`` (s) (MuJoCo; sensors ``noise`` at ``rate``
    Hz; QuadsimWarnings silenced)."""
    import warnings

    from quadsim.core.errors import QuadsimWarning
    from quadsim.effects import EffectSet
    from quadsim.logs.generate import generate_flight
    from quadsim.logs.sensors import SensorModel
    from quadsim.vehicle.params import load_params

    params = load_params(model)
    effects = EffectSet((make_effect("rotor_drag", coefficient=drag),
                         make_effect("motor_lag", time_constant=lag)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        log, _ = generate_flight(params, path, effects, SensorModel(noise=noise, rate=rate),
                                 seed, duration=duration, speed=speed, height=height,
                                 size=size)
    return params, log


def posefree_noise():
    """The sensor noise of the generated flights the pose-free tests cut (position 0.5 mm,
    velocity 0.01 m/s, attitude 2 mrad, gyro 0.02 rad/s, accelerometer 0.1 m/s^2, rotor
    speeds 10 rad/s; white)."""
    from quadsim.logs.sensors import SensorModel

    return SensorModel(noise={"position": 5e-4, "velocity": 0.01, "attitude": 2e-3,
                              "gyro": 0.02, "accel": 0.1, "rotor": 10.0})


#: the shared data's labelled real Crazyflie flights (tests that use them skip without it)
MIXED_DATA = ROOT.parent / "shared" / "data" / "crazyflie21_brushless"


def judge_real_cut(tmp_path: Path, keep, references, flights) -> dict:
    """The real Crazyflie flights cut to what a user may log, judged per flight as a user
    types it (``python -m quadsim.gap --model crazyflie21 --per-flight ... --reference ...
    --workers 1 --no-cache``): ``keep(log)`` -> the cut FlightLog; ``references`` the nominal
    flights' numbers (``nominal/flight_NN``), ``flights`` the mixed ones' (``mixed/flight_N``),
    each written cut into ``tmp_path``. Returns the result JSON's flights by file name."""
    import json
    import warnings

    from quadsim.core.errors import QuadsimWarning
    from quadsim.gap.__main__ import main
    from quadsim.logs.flightlog import load_log, write_log

    def cut(path: Path, folder: str) -> str:
        (tmp_path / folder).mkdir(exist_ok=True)
        return str(write_log(tmp_path / folder / path.name, keep(load_log(path, warn=False))))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [cut(MIXED_DATA / "nominal" / f"flight_{k:02d}.csv.gz", "ref")
                for k in references]
        judged = [cut(MIXED_DATA / "mixed" / f"flight_{k}.csv.gz", "fly") for k in flights]
    out = tmp_path / "out.json"
    assert main(["--model", "crazyflie21", "--per-flight", *judged, "--reference", *refs,
                 "--workers", "1", "--no-cache", "--quiet", "--json", str(out)]) == 0
    return {Path(f["file"]).name: f for f in json.loads(out.read_text())["flights"]}


def assert_payload_named(verdict: dict, total_kg: float = 0.0074, within: float = 0.002):
    """A mixed payload flight's verdict names a payload on a cable, its masses adding up to
    ``total_kg`` within ``within`` (kg)."""
    assert verdict["verdict"].startswith("cable_payload"), verdict["answer"]
    total = sum(v for k, v in verdict["params"].items() if k.endswith(".mass"))
    assert abs(total - total_kg) < within, verdict["params"]
