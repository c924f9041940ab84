"""The l2f flight source (benchmarks.l2f_source, l2f_cases): the vehicle as quadsim sees it,
the JSON parameter set handed to l2f, the controller's allocation, the frozen case list, and
-- with l2f installed (``pip install -e '.[l2f]'``) -- one short flight pair checked against
quadsim's own rigid-body and rotor model."""

from __future__ import annotations

import json
import types

import numpy as np
import pytest

from benchmarks.l2f_cases import case_list, library_truth, reference_specs
from benchmarks.l2f_source import (
    FS,
    MODEL,
    OMEGA_MAX,
    Cascade,
    FlightSpec,
    _flight_job,
    _parameters_json,
    hover_command,
    l2f_available,
    l2f_flights,
    vehicle_params,
)


def test_vehicle_as_quadsim_sees_it():
    """b = c2 / OMEGA_MAX^2 and d = k_Q b (l2f's reaction torque k_Q T); hover at a rotor
    state sqrt(m g / (4 c2)) = 0.5549 (l2f's own x500 header: 0.5549636); spins opposite to
    l2f's torque directions; the inertia the inverse of l2f's J^-1 (0.021705 kg m^2)."""
    p = vehicle_params()
    assert p.thrust_factor * OMEGA_MAX ** 2 == pytest.approx(MODEL["c2"], rel=1e-12)
    assert p.drag_factor == pytest.approx(MODEL["k_torque"] * p.thrust_factor, rel=1e-12)
    assert hover_command() == pytest.approx(0.5549636212401485, rel=1e-9)
    assert [r.spin for r in p.rotors] == [1.0, 1.0, -1.0, -1.0]
    assert p.inertia[0, 0] == pytest.approx(0.021705, rel=1e-4)
    np.testing.assert_allclose(p.motor_map.speed[0], p.motor_map.command * OMEGA_MAX)
    # quadsim's yaw torque -s d Omega^2 per rotor is l2f's k_Q T along its torque direction
    omega = 0.7 * OMEGA_MAX
    for rotor, direction in zip(p.rotors, MODEL["torque_dir"]):
        assert -rotor.spin * p.drag_factor * omega ** 2 == pytest.approx(
            direction * MODEL["k_torque"] * MODEL["c2"] * 0.7 ** 2, rel=1e-12)


def test_parameters_json_carries_the_job():
    """A +0.3 kg payload 40 mm off centre: l2f gets the rotors about the new CoM, the full
    inertia matrix and its inverse, a 1 kHz step; a weak rotor scales its coefficients."""
    job = _flight_job(FlightSpec(seed=1, effects={"payload": (0.3, 0.04, 0.0, -0.03),
                                                  "weak_rotor": (2, -0.1)}))
    template = json.dumps({"dynamics": {}, "integration": {"dt": 0.01}, "mdp": {}})
    p = json.loads(_parameters_json(job, template))
    d = p["dynamics"]
    assert p["integration"]["dt"] == pytest.approx(1e-3)
    assert d["mass"] == pytest.approx(2.3)
    np.testing.assert_allclose(np.array(d["J"]) @ np.array(d["J_inv"]), np.eye(3), atol=1e-12)
    com_x = 0.3 * 0.04 / 2.3
    assert d["rotor_positions"][0][0] == pytest.approx(0.176776695296636 - com_x, rel=1e-12)
    assert d["rotor_thrust_coefficients"][1][2] == pytest.approx(0.9 * MODEL["c2"])
    assert d["rotor_thrust_coefficients"][0][2] == pytest.approx(MODEL["c2"])
    assert d["J"][0][2] != 0.0                              # the payload below tilts the axes


def test_controller_allocation_hovers_level():
    """At hover, level, on its setpoint, the controller commands the hover state on every
    rotor (the allocation inverts the nominal mixer; 1e-9)."""
    ctrl = Cascade(0.002)
    z = np.zeros(3)
    u = ctrl.step(np.array([0, 0, 1.5]), z, np.array([1.0, 0, 0, 0]), z,
                  np.array([0, 0, 1.5]), z, z, 0.0)
    np.testing.assert_allclose(u, hover_command(), rtol=1e-9)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 30 frozen cases: 6 no-effect, 20 in-library, 4 outside; seeds apart from the
    references'; each in-library truth (but the delays) maps to the shared motor lag and body
    drag and its own library effect; magnitudes within the module table's ranges."""
    from quadsim.effects import EFFECTS

    cases = case_list()
    assert case_list() == cases and len(cases) == 30
    kinds = [c["kind"] for c in cases]
    assert (kinds.count("none"), kinds.count("library"), kinds.count("outside")) == (6, 20, 4)
    assert not {c["seed"] for c in cases} & {s.seed for s in reference_specs()}
    for case in cases:
        e = case["effects"]
        if case["kind"] == "library" and case["truth"] != "rotor_delay":
            names = [x.name for x in library_truth(case)]
            assert names[:2] == ["motor_lag", "body_drag"]
            assert case["truth"] in EFFECTS and (case["truth"] in names or len(names) == 2)
        if "mass" in e:
            assert 0.05 <= e["mass"] / MODEL["mass"] <= 0.2
        if "thrust_linear" in e:
            share = abs(e["thrust_linear"]) * hover_command() / (MODEL["mass"] * 9.81 / 4)
            assert 0.05 <= share <= 0.15
        if "motor_slow" in e:
            assert 1.5 <= e["motor_slow"] <= 2.5
        if "wind" in e:
            assert 2.0 <= np.hypot(*e["wind"]) <= 5.0


@pytest.mark.skipif(not l2f_available(), reason="l2f is not installed (pip install -e '.[l2f]')")
def test_flights_agree_with_quadsims_model():
    """A nominal flight (2.1 s logged) and a +0.3 kg flight (0.5 s), one process: 500 Hz,
    unit quaternions near level, commands in 0..1; the logged rotor speeds in quadsim's
    rotor model (b, d, arms, spins converted from l2f) with the shared body drag reproduce the
    logged specific force: the mean thrust is the accelerometer's body z force (1 %) and
    about the weight (3 %), and on the nominal flight quadsim's residual wrench stays below
    1.5 % of the weight (forces) and of weight x arm (torques) RMS; the logged speed
    follows the command through the 54 ms lag (the lag's closed form, 2 % of hover)."""
    from benchmarks.l2f_cases import shared_effects
    from benchmarks.l2f_source import l2f_flights
    from quadsim.gap.diagnose import prepare
    from quadsim.gap.fitting import residuals

    params = vehicle_params()
    base = FlightSpec(seed=5, speed=0.8, duration=2.1)
    heavy = FlightSpec(seed=6, speed=0.8, duration=0.5, effects={"mass": 0.3})
    (log, truth), (log_heavy, _) = l2f_flights([base, heavy], workers=1)
    assert truth["effects"] == {} and truth["source"] == "l2f"
    assert log.t[1] == pytest.approx(1.0 / 500)
    assert np.all(log.quat[:, 0] > 0.9)
    np.testing.assert_allclose(np.linalg.norm(log.quat, axis=1), 1.0, atol=1e-9)
    assert np.all((log.rotor_command >= 0) & (log.rotor_command <= 1))
    weight = params.mass * 9.81
    for flight, mass in ((log, params.mass), (log_heavy, params.mass + 0.3)):
        thrust = params.thrust_factor * np.sum(flight.rotor_speed ** 2, axis=1)
        assert np.mean(flight.accel[:, 2]) * mass == pytest.approx(np.mean(thrust), rel=0.01)
        assert np.mean(thrust) == pytest.approx(mass * 9.81, rel=0.03)
    flight = prepare([log], params)[0]
    r = residuals(flight.fit, params, shared_effects(), rotor_channel=False)
    rms = np.sqrt(np.mean(r ** 2, axis=0))
    assert np.all(rms[:3] < 0.015 * weight), rms
    assert np.all(rms[3:6] < 0.015 * weight * 0.25), rms
    # the rotor state follows the command through tau: Omega_k+1 ~ Omega_k + dt/tau (u - Omega)
    dt, tau = log.t[1] - log.t[0], MODEL["tau"]
    w, u = log.rotor_speed, log.rotor_command * OMEGA_MAX
    pred = w[:-1] + (1 - np.exp(-dt / tau)) * (u[1:] - w[:-1])
    hover = hover_command() * OMEGA_MAX
    assert np.sqrt(np.mean((pred - w[1:]) ** 2)) < 0.02 * hover


def test_the_fs_vehicle_as_quadsim_sees_it():
    """l2f's fs vehicle (thrust 0.785 + 9.155 a + 18.006 a^2 N per rotor): the hover state is
    the polynomial's root (a = 0.43667: four rotors carry 3.35 kg); the allocation inverts
    the polynomial; quadsim's b is the stand sweep's least squares through the origin,
    sum(T a^2) / sum(a^4) over a = 0.1..1.0 (closed form here, 30.13 a^2 N); the JSON gives
    l2f the curve's three terms, a linear case term added to c1."""
    from benchmarks.l2f_source import STAND, command_for, stand_b, thrust_of

    a = hover_command(vehicle=FS)
    assert thrust_of(a, FS) == pytest.approx(3.35 * 9.81 / 4, rel=1e-12)
    assert a == pytest.approx(0.43667, abs=1e-5)
    thrusts = np.array([1.0, 5.0, 12.0])
    np.testing.assert_allclose(thrust_of(command_for(thrusts, FS), FS), thrusts, rtol=1e-12)
    assert command_for(0.5, FS) == 0.0                      # below the constant term
    expected = np.sum(thrust_of(STAND, FS) * STAND ** 2) / np.sum(STAND ** 4)
    p = vehicle_params(FS)
    assert p.thrust_factor * 1000.0 ** 2 == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(30.13, abs=0.01)
    assert stand_b(MODEL) * OMEGA_MAX ** 2 == pytest.approx(MODEL["c2"], rel=1e-12)
    assert p.drag_factor == pytest.approx(0.01492 * p.thrust_factor, rel=1e-12)
    assert p.inertia[2, 2] == pytest.approx(7.296e-2 * 1.879, rel=1e-12)
    job = _flight_job(FlightSpec(seed=1, effects={"thrust_linear": 0.5}), FS)
    template = json.dumps({"dynamics": {}, "integration": {"dt": 0.01}, "mdp": {}})
    d = json.loads(_parameters_json(job, template))["dynamics"]
    assert d["rotor_thrust_coefficients"][0] == pytest.approx([FS["c0"], FS["c1"] + 0.5,
                                                               FS["c2"]], rel=1e-12)
    assert d["mass"] == pytest.approx(3.35) and d["rotor_time_constants_rising"][0] == 0.06532
    assert d["hovering_throttle_relative"] == pytest.approx(a, rel=1e-12)
    # the controller's allocation at hover: the hover state on every rotor
    ctrl = Cascade(0.002, FS)
    u = ctrl.step(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0]), np.zeros(3),
                  np.zeros(3), np.zeros(3), np.zeros(3), 0.0)
    np.testing.assert_allclose(u, a, rtol=1e-9)


def test_the_fs_cases_are_drawn_at_its_scale():
    """The fs source's frozen cases: 30, the X500's table, its own seeds, masses +5..+20 %
    of 3.35 kg, the truth's shared physics with the thrust curve against the stand fit."""
    from benchmarks.l2f_fs_cases import SOURCE, case_list

    cases = case_list()
    assert len(cases) == 30 and SOURCE.name == "l2f-fs"
    assert {c["vehicle"] for c in cases} == {"l2f-fs"} and cases[0]["seed"] == 81_000
    masses = [c["effects"]["mass"] for c in cases if c["case"] == "mass_offset"]
    assert masses and all(0.05 * 3.35 <= m <= 0.2 * 3.35 for m in masses)
    from benchmarks.l2f_cases import FS_CASES
    names = [e.name for e in FS_CASES.shared_effects()]
    assert names == ["motor_lag", "body_drag", "thrust_factor", "thrust_curve"]


def _curved_vehicle(vehicle: dict, hover: float, max_speed: float, module: str, seed0: int):
    """A curved-rotor vehicle's common checks: the hover state is the polynomial's root
    c0 + c1 a + c2 a^2 = m g / 4 (``hover``, 1e-4), its parameter set's mass and full speed,
    its 30 frozen cases at its scale (masses +5..+20 %) with its own seeds, and its truth's
    shared physics: the rotor lag, the body drag, the propeller factor c2 / (b w^2) and the
    curve's terms divided by that factor (a propeller factor scales the whole curve).
    Returns the truth's shared effects and the factor."""
    import importlib

    from benchmarks import l2f_cases

    c0, c1, c2, m = vehicle["c0"], vehicle["c1"], vehicle["c2"], vehicle["mass"]
    a = hover_command(vehicle=vehicle)
    assert a == pytest.approx((-c1 + np.sqrt(c1 ** 2 + 4 * c2 * (m * 9.81 / 4 - c0)))
                              / (2 * c2), rel=1e-12)
    assert a == pytest.approx(hover, abs=1e-4)
    p = vehicle_params(vehicle)
    assert p.mass == m and p.max_speed == max_speed
    mod = importlib.import_module(f"benchmarks.{module}")
    cases = mod.case_list()
    assert len(cases) == 30 and mod.SOURCE.name == vehicle["name"]
    assert {c["vehicle"] for c in cases} == {vehicle["name"]} and cases[0]["seed"] == seed0
    masses = [c["effects"]["mass"] for c in cases if c["case"] == "mass_offset"]
    assert masses and all(0.05 * m <= x <= 0.2 * m for x in masses)
    table = next(v for v in vars(l2f_cases).values()
                 if isinstance(v, l2f_cases.VehicleCases) and v.vehicle is vehicle)
    shared, factor = table.shared_effects(), table.curve_factor()
    assert [e.name for e in shared] == ["motor_lag", "body_drag", "thrust_factor",
                                        "thrust_curve"]
    assert shared[2].change == pytest.approx(factor - 1)
    assert shared[-1].offset * factor == pytest.approx(c0)
    assert shared[-1].linear * factor == pytest.approx(c1 / max_speed)
    return shared, factor


def test_the_flightmare_vehicle_and_its_cases():
    """l2f's flightmare vehicle (thrust -1.769 + 11.508 a + 11.968 a^2 N per rotor): hover at
    a = 0.2462 (four rotors carry 0.73 kg); zero thrust is commanded at the curve's own root
    (a = 0.1348), never below it (no negative thrust asked for); its cases and truth as
    :func:`_curved_vehicle` (its -1.769 N constant inside the library's range)."""
    from benchmarks.l2f_source import FLIGHTMARE, command_for, thrust_of

    _curved_vehicle(FLIGHTMARE, 0.2462, 3000.0, "l2f_flightmare_cases", 82_000)
    assert command_for(0.0, FLIGHTMARE) == pytest.approx(0.1348, abs=1e-4)
    assert thrust_of(command_for(0.0, FLIGHTMARE), FLIGHTMARE) == pytest.approx(0.0, abs=1e-12)


def test_the_mrs_vehicle_and_its_cases():
    """l2f's mrs vehicle (1.7 kg on the flightmare vehicle's rotors; its rotor state in rad/s
    up to 2000, so -1.769 + 7.672 a + 5.319 a^2 N at a = Omega / 2000): hover at a = 0.558;
    its truth's propeller factor (0.45: the stand's b is 2.2x c2) is built beyond a
    reading's plausible range; cases and truth as :func:`_curved_vehicle`."""
    from benchmarks.l2f_source import MRS

    assert (MRS["c1"], MRS["c2"]) == pytest.approx((7.672162, 5.319301), rel=1e-6)
    _, factor = _curved_vehicle(MRS, 0.5581, 2000.0, "l2f_mrs_cases", 84_000)
    assert factor == pytest.approx(0.4511, abs=1e-3)


@pytest.mark.skipif(not l2f_available(), reason="l2f is not installed (pip install -e '.[l2f]')")
def test_the_references_share_their_thrust_curves_slope():
    """The fs vehicle's thrust curve (0.785 + 9.16 a + 18.0 a^2 N per rotor) has at hover
    0.66 of the slope the quadratic model gives (2 T / Omega). Four nominal flights (4 s)
    share the curve's slope about their mean rotor speed (quadsim.gap.calibrate.centred_curve):
    the reference model's slope is the closed form dT/dOmega - 2 T / Omega there (5 %), and
    its inertia no longer absorbs the torque error (within 5 % of the truth; +51 % with b
    alone). A +0.5 kg flight is then named a mass, within 10 % (its lead was a thrust curve
    before, at 0.60)."""
    from benchmarks.l2f_source import thrust_of
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare

    params = vehicle_params(FS)
    specs = [FlightSpec(seed=70 + k, speed=0.8 + 0.15 * k, duration=4.0) for k in range(4)]
    specs.append(FlightSpec(seed=80, speed=1.0, duration=4.0, effects={"mass": 0.5}))
    flown = l2f_flights(specs, workers=1, vehicle="fs")
    ref = calibrate(prepare([log for log, _ in flown[:4]], params), params)
    centre = next(f["centre"] for n, f, _ in ref.candidate.parts if n == "thrust_curve")
    w = FS["omega_max"]
    a = centre / w
    slope = (thrust_of(a + 1e-6, FS) - thrust_of(a - 1e-6, FS)) / (2e-6 * w)
    values = ref.values()
    assert values["thrust_curve.linear"] == pytest.approx(
        slope - 2 * thrust_of(a, FS) / centre, rel=0.05)
    for axis in ("xx", "yy"):
        assert abs(values[f"inertia_error.{axis}"]) < 0.05
    # the curvature about the centre, b + quadratic, against the curve's c2 / w^2 (0.42 of
    # the stand's b): 1.90e-5 for 1.80e-5 measured
    b = params.thrust_factor * (1 + values["nominal_refit.thrust"])
    assert b + values["thrust_curve.quadratic"] == pytest.approx(FS["c2"] / w ** 2, rel=0.15)
    entry = judge_one(flown[4][0], ref)
    assert entry["verdict"] == "mass_offset", entry["answer"]
    assert entry["params"]["mass_offset.mass"] == pytest.approx(0.5, rel=0.1)


@pytest.mark.skipif(not l2f_available(), reason="l2f is not installed (pip install -e '.[l2f]')")
def test_a_com_offset_on_a_curved_rotor_is_not_a_payload():
    """l2f's mrs vehicle hovers where its curve's curvature (c2 / w^2) is 0.40 of the b that
    carries the hover. A CoM offset spreads the rotor speeds, and with b Omega^2 alone the
    model over-predicts the summed thrust there: the offset of (-9, 12) mm was read as a
    payload (mass_offset, 0.60; before the shared curvature). With the references' curvature
    about their hover shared (thrust_curve.quadratic, a prior of half of b) it is a CoM
    offset (measured -5.5, 10.9 mm), and a +0.25 kg payload stays a mass."""
    from benchmarks.l2f_source import MRS
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare

    params = vehicle_params(MRS)
    specs = [FlightSpec(seed=70 + k, speed=0.8 + 0.15 * k, duration=8.0) for k in range(4)]
    specs += [FlightSpec(seed=80, speed=1.0, duration=4.0, effects={"mass": 0.25}),
              FlightSpec(seed=81, speed=1.0, duration=4.0, effects={"com": (-0.009, 0.012)})]
    flown = l2f_flights(specs, workers=1, vehicle="mrs")
    ref = calibrate(prepare([log for log, _ in flown[:4]], params), params)
    mass, com = (judge_one(log, ref) for log, _ in flown[4:])
    assert mass["verdict"] == "mass_offset", mass["answer"]
    assert mass["params"]["mass_offset.mass"] == pytest.approx(0.25, rel=0.05)
    assert com["verdict"] == "com_offset", com["answer"]
    assert com["params"]["com_offset.x"] == pytest.approx(-0.009, abs=0.005)
    assert com["params"]["com_offset.y"] == pytest.approx(0.012, abs=0.002)


def test_the_arpl_vehicle_and_its_cases():
    """l2f's arpl vehicle (-0.530 + 8.971 a - 0.891 a^2 N per rotor: a curve that bends
    down): hover at a = 0.2807 (four rotors carry 0.782 kg); quadsim's b is the stand fit over
    the band it flies (a = 0.1..0.5), 1.40x low at hover (2.7x over 0.1..1.0, beyond the
    vehicle check's 2x); its truth states the curve exactly with no propeller factor (b
    Omega^2 plus the curve's linear, constant and curvature terms: 1e-12 N at four speeds);
    30 cases at its scale with their own seeds."""
    from benchmarks.l2f_arpl_cases import SOURCE, case_list
    from benchmarks.l2f_cases import ARPL_CASES
    from benchmarks.l2f_source import ARPL, thrust_of

    a = hover_command(vehicle=ARPL)
    assert a == pytest.approx(0.2807, abs=1e-4)
    p = vehicle_params(ARPL)
    assert 1.9178 / (a * 3000.0) ** 2 / p.thrust_factor == pytest.approx(1.40, abs=0.01)
    shared = ARPL_CASES.shared_effects()
    assert [e.name for e in shared] == ["motor_lag", "body_drag", "thrust_curve"]
    assert ARPL_CASES.curve_factor() == 1.0
    speed = np.array([[300.0, 842.0, 1500.0, 2800.0]])
    ctx = types.SimpleNamespace(rotor_speed=speed)
    model = p.thrust_factor * speed ** 2 + shared[-1].loads(ctx).curve_offset
    np.testing.assert_allclose(model, thrust_of(speed / 3000.0, ARPL), atol=1e-12)
    cases = case_list()
    assert len(cases) == 30 and SOURCE.name == "l2f-arpl" and cases[0]["seed"] == 85_000
    coms = [np.hypot(*c["effects"]["com"]) for c in cases if c["case"] == "com_offset"]
    assert coms and max(coms) <= 0.1 * 0.0775 * np.sqrt(2)


@pytest.mark.skipif(not l2f_available(), reason="l2f is not installed (pip install -e '.[l2f]')")
def test_a_thrust_curve_that_bends_down_is_read_against_references_that_bend_down():
    """l2f's arpl vehicle's curve bends down (c2 < 0: -0.04 of the b at its hover). Its
    references' shared curvature ``b + quadratic`` must go below zero
    (priors.curve_quadratic_bounds, -b..2b): with the bound at 0 it stopped there, and a
    flight whose linear term is -0.7 or +0.9 N per unit state was read as a mass of +89 or
    -92 g (0.62, 0.67). Below zero, both are `thrust_curve`, each at its value per rad/s
    (-0.7 / 3000 and 0.9 / 3000, within 5 %)."""
    from benchmarks.l2f_source import ARPL
    from quadsim.gap.calibrate import calibrate
    from quadsim.gap.diagnose import judge_one, prepare

    params = vehicle_params(ARPL)
    specs = [FlightSpec(seed=70 + k, speed=0.8 + 0.15 * k, duration=8.0) for k in range(4)]
    specs += [FlightSpec(seed=80 + k, speed=1.0, duration=4.0, effects={"thrust_linear": c})
              for k, c in enumerate((-0.7, 0.9))]
    flown = l2f_flights(specs, workers=1, vehicle="arpl")
    ref = calibrate(prepare([log for log, _ in flown[:4]], params), params)
    values = ref.values()
    assert params.thrust_factor * (1 + values["nominal_refit.thrust"]) \
        + values["thrust_curve.quadratic"] < 0.0
    for (log, _), c in zip(flown[4:], (-0.7, 0.9)):
        entry = judge_one(log, ref)
        assert entry["verdict"] == "thrust_curve", entry["answer"]
        assert entry["params"]["thrust_curve.linear"] == pytest.approx(c / 3000.0, rel=0.05)


def test_the_soft_vehicle_and_its_cases():
    """l2f's soft_rigid vehicle (-0.334 + 6.091 a + 0.782 a^2 N per rotor): hover at a =
    0.3617; quadsim's b is the stand fit over a = 0.1..0.6, 1.31x low at hover; its c2 is
    0.068 of the stand's b at full speed, below MIN_CURVE_FACTOR, so its truth states the curve
    exactly with no propeller factor (1e-12 N at four speeds); 30 cases with their own seeds
    and CoM offsets within 10 % of the 0.142 m arm."""
    from benchmarks.l2f_cases import MIN_CURVE_FACTOR, SOFT_CASES
    from benchmarks.l2f_soft_cases import SOURCE, case_list
    from benchmarks.l2f_source import SOFT, stand_b, thrust_of

    a = hover_command(vehicle=SOFT)
    assert a == pytest.approx(0.3617, abs=1e-4)
    p = vehicle_params(SOFT)
    assert 0.804 * 9.81 / 4 / (a * 2500.0) ** 2 / p.thrust_factor == pytest.approx(1.31, abs=0.01)
    assert SOFT["c2"] / (stand_b(SOFT) * 2500.0 ** 2) == pytest.approx(0.068, abs=0.001)
    assert 0.068 < MIN_CURVE_FACTOR and SOFT_CASES.curve_factor() == 1.0
    shared = SOFT_CASES.shared_effects()
    assert [e.name for e in shared] == ["motor_lag", "body_drag", "thrust_curve"]
    speed = np.array([[300.0, 905.0, 1500.0, 2400.0]])
    model = p.thrust_factor * speed ** 2 \
        + shared[-1].loads(types.SimpleNamespace(rotor_speed=speed)).curve_offset
    np.testing.assert_allclose(model, thrust_of(speed / 2500.0, SOFT), atol=1e-12)
    cases = case_list()
    assert len(cases) == 30 and SOURCE.name == "l2f-soft" and cases[0]["seed"] == 86_000
    coms = [np.hypot(*c["effects"]["com"]) for c in cases if c["case"] == "com_offset"]
    assert coms and max(coms) <= 0.1 * 0.142 * np.sqrt(2)


def test_the_cascades_rate_integral_holds_a_com_offsets_torque():
    """The cascade's rate integral is clipped as a torque: it can hold a CoM offset at 15 %
    of the arm on every vehicle (``i_rate_max = 0.15 m g arm / (J K_I)``, at least the 0.5
    rad it was). At 0.5 rad the arpl vehicle held 2.7 mN m against a 5.7 mm offset's 44 mN m,
    and its CoM flights drifted 40-70 m in 8 s; with it, the same flight stays within 7 m
    (its path spans +-2.7 m)."""
    from benchmarks.l2f_source import ARPL

    ctrl = Cascade(0.002, ARPL)
    arm = float(np.hypot(0.0775, 0.0981))
    expected = 0.15 * 0.782 * 9.81 * arm / (np.array(ARPL["inertia"]) * Cascade.KI_RATE)
    np.testing.assert_allclose(ctrl.i_rate_max, expected, rtol=1e-12)
    assert ctrl.i_rate_max[0] == pytest.approx(27.15, abs=0.01)
    assert Cascade(0.002, MODEL).i_rate_max[0] == pytest.approx(11.3, abs=0.05)
    if not l2f_available():
        pytest.skip("l2f is not installed (pip install -e '.[l2f]')")
    spec = FlightSpec(seed=85009, speed=0.911, duration=8.0, effects={"com": (0.0057, 0.0006)})
    (log, _), = l2f_flights([spec], workers=1, vehicle="arpl")
    assert np.max(np.abs(log.position[:, :2])) < 7.0
