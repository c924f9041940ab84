"""The gym-pybullet-drones flight source (benchmarks.gpd_source, gpd_cases): the cf2x
parameter set against the aviary's own formulas, the frozen case list, and -- with the
simulator installed (``pip install pybullet==3.2.7 gymnasium transforms3d``, ``pip install
--no-deps swarm-drone-gym==2.0.0.3``) -- the URDF values as the aviary parses them,
pybullet's default damping, and one short flight pair checked against quadsim's model."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.gpd_source import (
    MODEL,
    RPM,
    FlightSpec,
    gpd_available,
    hover_speed_of,
    max_speed,
    vehicle_params,
)
from quadsim.vehicle.rotors import rotor_wrench

needs_gpd = pytest.mark.skipif(not gpd_available(), reason="gym-pybullet-drones is not "
                               "installed")


def test_hover_and_max_speed_closed_form():
    """Hover: sqrt(m g / 4 kf) = sqrt(0.027 x 9.8 / 1.264e-9) = 14468.4 RPM = 1515.1 rad/s;
    MAX_RPM = hover x sqrt(2.25) = 21702.6 RPM; the parameter set's b Omega^2 at hover carries
    the weight (1e-12)."""
    assert hover_speed_of() / RPM == pytest.approx(14468.43, abs=0.01)
    assert hover_speed_of() == pytest.approx(1515.13, abs=0.01)
    assert max_speed() / RPM == pytest.approx(21702.64, abs=0.01)
    params = vehicle_params()
    assert 4 * params.thrust_factor * hover_speed_of() ** 2 == pytest.approx(
        MODEL["mass"] * MODEL["gravity"], rel=1e-12)


def test_x_layout_matches_the_aviarys_torques():
    """quadsim's rotor model of the parameter set gives the aviary's forces and torques for
    random RPMs: thrust kf sum rpm^2; roll sum y_i f_i = (-f0 - f1 + f2 + f3) 0.028 m and
    pitch -sum x_i f_i = (-f0 + f1 + f2 - f3) 0.028 m (the propeller links at (+-0.028,
    +-0.028) where pybullet applies each force under Physics.PYB*; the aviary's explicit
    Physics.DYN writes roll with the opposite sign and is not used); yaw km (-rpm0^2 +
    rpm1^2 - rpm2^2 + rpm3^2) (BaseAviary._physics; 1e-12)."""
    params = vehicle_params()
    rng = np.random.default_rng(4)
    for rpm in rng.uniform(9000.0, 21000.0, (5, 4)):
        f = MODEL["kf"] * rpm ** 2
        t = MODEL["km"] * rpm ** 2
        force, torque = rotor_wrench(params, rpm * RPM)
        assert force[2] == pytest.approx(f.sum(), rel=1e-12)
        expected = np.array([(-f[0] - f[1] + f[2] + f[3]) * 0.028,
                             (-f[0] + f[1] + f[2] - f[3]) * 0.028,
                             -t[0] + t[1] - t[2] + t[3]])
        np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-18)


def test_case_list_frozen_and_mapped_to_the_library():
    """The 22 frozen cases, the same on a second draw: 6 no-effect, 14 in-library, 2 outside;
    seeds apart from the references'; each in-library truth is a library effect named by
    its true difference on top of the three shared effects (the drag cases: the shared drag
    scaled); the drawn changes within the module table's ranges."""
    from benchmarks import gpd_cases
    from quadsim.effects import EFFECTS

    cases = gpd_cases.case_list()
    assert gpd_cases.case_list() == cases and len(cases) == 22
    kinds = [c["kind"] for c in cases]
    assert (kinds.count("none"), kinds.count("library"), kinds.count("outside")) == (6, 14, 2)
    assert not {c["seed"] for c in cases} & {s.seed for s in gpd_cases.reference_specs()}
    shared = ("rotor_drag", "body_drag", "rate_damping")
    for case in cases:
        e = case["effects"]
        if case["kind"] == "library":
            names = [x.name for x in gpd_cases.library_truth(case)]
            assert tuple(names[:3]) == shared, names
            assert case["truth"] in EFFECTS
            assert case["truth"] in names[3:] or (case["truth"] == "rotor_drag"
                                                  and len(names) == 3)
        if "mass" in e:
            assert 0.05 <= e["mass"] / MODEL["mass"] <= 0.2
        if "com" in e:
            assert 0.01 <= np.hypot(*e["com"]) / MODEL["arm"] <= 0.023
        if "weak_rotor" in e:
            assert -0.08 <= e["weak_rotor"][1] <= -0.03
        if "drag_scale" in e:
            assert e["drag_scale"] == 0.0 or 1.5 <= e["drag_scale"] <= 2.5
        if "wind" in e:
            assert 1.0 <= np.hypot(*e["wind"]) <= 2.5
    drag = gpd_cases.shared_effects(0.0)[0]
    linear = 0.04 * 0.027 / (4 * hover_speed_of())
    assert drag.coefficient == pytest.approx(linear, rel=1e-12)


@needs_gpd
def test_urdf_values_as_the_aviary_parses_them():
    """MODEL is cf2x.urdf as the installed aviary reads it (mass, arm, kf, km, inertia, drag,
    propeller radius, MAX_RPM; 1e-12)."""
    from gym_pybullet_drones.envs.CtrlAviary import CtrlAviary
    from gym_pybullet_drones.utils.enums import DroneModel

    env = CtrlAviary(drone_model=DroneModel.CF2X, gui=False)
    try:
        assert env.M == MODEL["mass"] and env.L == MODEL["arm"]
        assert env.KF == MODEL["kf"] and env.KM == MODEL["km"]
        np.testing.assert_allclose(np.diag(env.J), MODEL["inertia"], rtol=1e-12)
        np.testing.assert_allclose(env.DRAG_COEFF, [MODEL["drag_xy"], MODEL["drag_xy"],
                                                    MODEL["drag_z"]], rtol=1e-12)
        assert env.PROP_RADIUS == MODEL["prop_radius"] and env.G == MODEL["gravity"]
        assert env.MAX_RPM * RPM == pytest.approx(max_speed(), rel=1e-12)
    finally:
        env.close()


@needs_gpd
def test_pybullets_default_damping():
    """pybullet's multibody damping the aviary leaves on: in one 2 ms step without gravity or
    force, a speed v decays at (0.04 + 0.04 |v|) per second, a body rate alike (1e-6)."""
    import pybullet as p
    from gym_pybullet_drones.envs.CtrlAviary import CtrlAviary
    from gym_pybullet_drones.utils.enums import DroneModel

    env = CtrlAviary(drone_model=DroneModel.CF2X, gui=False, pyb_freq=500, ctrl_freq=500,
                     initial_xyzs=np.array([[0.0, 0.0, 5.0]]))
    try:
        env.reset()
        body, client = env.DRONE_IDS[0], env.CLIENT
        p.setGravity(0, 0, 0, physicsClientId=client)
        for v in (1.0, 4.0):
            for linear in (True, False):
                p.resetBasePositionAndOrientation(body, [0, 0, 5], [0, 0, 0, 1],
                                                  physicsClientId=client)
                p.resetBaseVelocity(body, [v, 0, 0] if linear else [0, 0, 0],
                                    [0, 0, 0] if linear else [v, 0, 0],
                                    physicsClientId=client)
                p.stepSimulation(physicsClientId=client)
                after = p.getBaseVelocity(body, physicsClientId=client)[0 if linear else 1][0]
                assert (v - after) / 0.002 / v == pytest.approx(0.04 + 0.04 * v, abs=1e-6)
    finally:
        env.close()


@needs_gpd
def test_flights_agree_with_quadsims_model():
    """A nominal flight (2.1 s logged) and a +2.7 g flight (0.5 s), one process, checked by
    ``_helpers.check_source_flight`` against quadsim's model with the shared drag and
    damping; the logged rotor speed is the command x MAX_RPM (1e-9)."""
    from benchmarks.gpd_cases import shared_effects
    from benchmarks.gpd_source import gpd_flights
    from benchmarks.tests._helpers import check_source_flight

    base = FlightSpec(seed=5, speed=0.8, duration=2.1)
    heavy = FlightSpec(seed=6, speed=0.8, duration=0.5, effects={"mass": 0.0027})
    (log, truth), (log_heavy, _) = gpd_flights([base, heavy])
    assert truth["effects"] == {} and truth["source"] == "gym-pybullet-drones"
    check_source_flight(log, log_heavy, vehicle_params(), 0.0027, shared_effects(),
                        MODEL["arm"])
    noise = 0.003 * hover_speed_of()
    assert np.std(log.rotor_speed - log.rotor_command * max_speed()) == pytest.approx(
        noise, rel=0.05)
