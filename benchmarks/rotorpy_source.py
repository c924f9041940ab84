"""Independent flights from RotorPy (closed loop, its own controller, integrator and sensors).

RotorPy (Folk et al., "RotorPy: A Python-based multirotor simulator with aerodynamics for
education and research", arXiv:2306.04485; ``pip install rotorpy``, tested with 3.0.0) flies
the vehicle with its own SE(3) controller
(:class:`rotorpy.controllers.quadrotor_control.SE3Control`, which knows only the *nominal*
parameters), its own integrator (``scipy.integrate.solve_ivp`` RK45 per step in
:class:`rotorpy.vehicles.multirotor.Multirotor`), its own first-order motor model, its own
aerodynamics (parasitic drag, rotor drag, flapping, translational lift) and its own sensor models
(:class:`rotorpy.sensors.imu.Imu`, :class:`rotorpy.sensors.external_mocap.MotionCapture`). Nothing
of quadsim's effect hooks is used: an effect is injected as RotorPy parameters.

Conversion of a quadsim parameter set into RotorPy's ``quad_params`` (:func:`quad_params`):
mass (kg), Ixx..Izz (kg m^2), rotor positions relative to the CoM (m), ``k_eta = b``
(N s^2/rad^2), ``k_m = d`` (N m s^2/rad^2), ``rotor_directions = -spin`` (RotorPy's yaw
torque is ``+dir k_m Omega^2``; quadsim's ``-spin d Omega^2`` with spin +1 ccw),
``rotor_speed_max = max_speed`` (rad/s), ``tau_m = NOMINAL_TAU_M`` (s; quadsim's nominal
model has no motor lag, a real ESC has a few ms) and no aerodynamics.

Effects (:data:`EFFECTS`, values in SI): ``mass`` (kg added at the CoM), ``com`` (m, x y:
the CoM moves, so every rotor position relative to it moves by -com), ``inertia`` (relative
change of Ixx Iyy Izz), ``weak_rotor`` (rotor index 1..4, relative change of that rotor's
k_eta and k_m; RotorPy has one k_eta for all rotors, so :class:`_PerRotorMultirotor` adds the
difference of that rotor's thrust and torque to RotorPy's own wrench), ``thrust_scale``
(relative change of k_eta and k_m of all rotors: a propeller/air change), ``tau_m`` (s),
``c_d`` (N/(m/s)^2 parasitic drag, all axes), ``k_d``/``k_z`` (kg/rad rotor drag),
``wind`` (m/s world x y, RotorPy ``ConstantWind``), ``gust`` (m/s amplitude, RotorPy
``SinusoidWind`` at 0.3 Hz), ``k_flap`` (N m/(rad m/s), flapping moment) and ``k_h``
(kg/m, translational lift); the last three are outside quadsim's effect library.

Output (:func:`rotorpy_flight`): a :class:`quadsim.logs.flightlog.FlightLog` at the simulation
rate: position/velocity/attitude from RotorPy's motion capture (its quaternion xyzw is
reordered to wxyz, body to world), gyro and specific force (body, m/s^2) from its IMU,
rotor speeds as RotorPy's state reports them (rad/s), commands = RotorPy's commanded speed /
max_speed (normalised 0-1, like :func:`quadsim.logs.generate.generate_flight`).

Example::

    >>> from quadsim.vehicle.params import load_params
    >>> log = rotorpy_flight(load_params("crazyflie21"), {"mass": 0.004}, seed=1)
"""

from __future__ import annotations

import numpy as np

from quadsim.effects.battery_sag import nominal_voltage
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import VehicleParams

__all__ = ["EFFECTS", "NOMINAL_TAU_M", "quad_params", "rotorpy_available", "rotorpy_flight"]

#: s; nominal motor time constant given to RotorPy (quadsim's nominal model has none).
NOMINAL_TAU_M = 0.005
EFFECTS = ("mass", "com", "inertia", "weak_rotor", "thrust_scale", "tau_m", "c_d", "k_d", "k_z",
           "wind", "gust", "k_flap", "k_h")


def rotorpy_available() -> bool:
    try:
        import rotorpy.vehicles.multirotor  # noqa: F401
    except ImportError:
        return False
    return True


def quad_params(params: VehicleParams, effects: dict | None = None) -> dict:
    """RotorPy ``quad_params`` of ``params`` with ``effects`` (see the module docstring)."""
    effects = dict(effects or {})
    unknown = set(effects) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown RotorPy effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    inertia = np.asarray(params.inertia, dtype=float)
    scale = 1.0 + np.asarray(effects.get("inertia", (0.0, 0.0, 0.0)), dtype=float)
    com = np.zeros(3)
    com[:2] = effects.get("com", (0.0, 0.0))
    positions = np.asarray(params.rotor_positions, dtype=float) - np.asarray(params.com) - com
    c_d = float(effects.get("c_d", 0.0))
    return {
        "mass": params.mass + float(effects.get("mass", 0.0)),
        "Ixx": inertia[0, 0] * scale[0], "Iyy": inertia[1, 1] * scale[1],
        "Izz": inertia[2, 2] * scale[2],
        "Ixy": inertia[0, 1], "Ixz": inertia[0, 2], "Iyz": inertia[1, 2],
        "num_rotors": params.rotor_count,
        "rotor_pos": {f"r{i + 1}": positions[i] for i in range(params.rotor_count)},
        "rotor_directions": -np.asarray(params.rotor_spins, dtype=float),
        "rI": np.zeros(3),
        "c_Dx": c_d, "c_Dy": c_d, "c_Dz": c_d,
        "k_eta": params.thrust_factor * (1.0 + float(effects.get("thrust_scale", 0.0))),
        "k_m": params.drag_factor * (1.0 + float(effects.get("thrust_scale", 0.0))),
        "k_d": float(effects.get("k_d", 0.0)), "k_z": float(effects.get("k_z", 0.0)),
        "k_h": float(effects.get("k_h", 0.0)), "k_flap": float(effects.get("k_flap", 0.0)),
        "tau_m": float(effects.get("tau_m", NOMINAL_TAU_M)),
        "rotor_speed_min": 0.0, "rotor_speed_max": params.max_speed, "motor_noise_std": 0.0,
    }


def _per_rotor_vehicle(qp: dict, weak: tuple[int, float] | None, initial: dict):
    from rotorpy.vehicles.multirotor import Multirotor

    class _PerRotorMultirotor(Multirotor):
        """RotorPy's Multirotor with one rotor's k_eta and k_m scaled by (1 + delta)."""

        def compute_body_wrench(self, body_rates, rotor_speeds, body_airspeed_vector):
            force, moment = super().compute_body_wrench(body_rates, rotor_speeds,
                                                        body_airspeed_vector)
            if weak is not None:
                i, delta = weak
                extra = np.array([0.0, 0.0, delta * self.k_eta * rotor_speeds[i] ** 2])
                force = force + extra
                moment = moment + np.cross(self.rotor_geometry[i], extra)
                moment[2] += self.rotor_dir[i] * delta * self.k_m * rotor_speeds[i] ** 2
            return force, moment

    return _PerRotorMultirotor(qp, initial_state=initial, control_abstraction="cmd_motor_speeds",
                               aero=True)


class _Yaw:
    """Gentle sinusoidal yaw reference (rad) for the circular trajectory."""

    def __init__(self, amplitude: float, omega: float):
        self.a, self.w = amplitude, omega

    def update(self, t, x_dot):
        a, w = self.a, self.w
        return {"yaw": a * np.sin(w * t), "yaw_dot": a * w * np.cos(w * t),
                "yaw_ddot": -a * w * w * np.sin(w * t)}


def rotorpy_flight(params: VehicleParams, effects: dict | None = None, *, seed: int = 0,
                   duration: float = 6.0, rate_hz: float = 250.0, speed: float = 1.0,
                   name: str = "rotorpy") -> FlightLog:
    """Fly ``params`` + ``effects`` in RotorPy along a 3-D Lissajous circle; see the module
    docstring. ``speed`` scales the path frequency (1 = about 1.2 m/s for a 1 m vehicle
    scale; the path size scales with the vehicle's arm length)."""
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.sensors.external_mocap import MotionCapture
    from rotorpy.sensors.imu import Imu
    from rotorpy.trajectories.circular_traj import ThreeDCircularTraj
    from rotorpy.wind.default_winds import ConstantWind, NoWind, SinusoidWind

    effects = dict(effects or {})
    np.random.seed(seed)  # RotorPy's sensors draw from numpy's global generator
    rng = np.random.default_rng(seed)
    nominal = quad_params(params)
    truth = quad_params(params, {k: v for k, v in effects.items() if k != "weak_rotor"
                                 and k not in ("wind", "gust")})
    size = 1.0 if params.mass > 0.2 else 0.5
    base = 0.2 * speed * rng.uniform(0.85, 1.15)
    traj = ThreeDCircularTraj(center=np.array([0.0, 0.0, 1.0]),
                              radius=np.array([size, size, 0.25 * size]),
                              freq=np.array([base, base, 1.7 * base]),
                              yaw_traj=_Yaw(0.4, 1.3 * speed))
    flat0 = traj.update(0.0)
    hover = np.sqrt(truth["mass"] * 9.81 / (params.rotor_count * params.thrust_factor))
    initial = {"x": flat0["x"], "v": flat0["x_dot"], "q": np.array([0.0, 0.0, 0.0, 1.0]),
               "w": np.zeros(3), "wind": np.zeros(3),
               "rotor_speeds": np.full(params.rotor_count, hover)}
    weak = effects.get("weak_rotor")
    vehicle = _per_rotor_vehicle(truth, (int(weak[0]) - 1, float(weak[1])) if weak else None,
                                 initial)
    controller = SE3Control(nominal)
    if "wind" in effects:
        wind = ConstantWind(effects["wind"][0], effects["wind"][1], 0.0)
    elif "gust" in effects:
        g = float(effects["gust"])
        wind = SinusoidWind(np.array([g, g, 0.0]), np.array([0.3, 0.23, 0.0]), np.zeros(3))
    else:
        wind = NoWind()
    imu = Imu(sampling_rate=rate_hz)
    mocap = MotionCapture(sampling_rate=rate_hz, mocap_params={
        "pos_noise_density": 5e-4 / np.sqrt(rate_hz / 2) * np.ones(3),
        "vel_noise_density": 0.01 / np.sqrt(rate_hz / 2) * np.ones(3),
        "att_noise_density": 2e-3 / np.sqrt(rate_hz / 2) * np.ones(3),
        "rate_noise_density": 0.02 / np.sqrt(rate_hz / 2) * np.ones(3),
        "vel_artifact_max": 0.0, "vel_artifact_prob": 0.0,
        "rate_artifact_max": 0.0, "rate_artifact_prob": 0.0})
    dt = 1.0 / rate_hz
    n = round(duration * rate_hz) + 1
    state = {k: np.array(v, dtype=float) for k, v in initial.items()}
    rows = {k: [] for k in ("x", "v", "q", "gyro", "accel", "rotor", "cmd")}
    for k in range(n):
        t = k * dt
        state["wind"] = wind.update(t, state["x"])
        flat = traj.update(t)
        control = controller.update(t, state, flat)
        sdot = vehicle.statedot(state, control, dt)
        meas = imu.measurement(state, sdot, with_noise=True)
        mc = mocap.measurement(state, with_noise=True, with_artifacts=False)
        rows["x"].append(mc["x"])
        rows["v"].append(mc["v"])
        rows["q"].append(mc["q"])
        rows["gyro"].append(meas["gyro"])
        rows["accel"].append(meas["accel"])
        rows["rotor"].append(state["rotor_speeds"].copy())
        rows["cmd"].append(np.clip(control["cmd_motor_speeds"], 0.0, params.max_speed))
        if k + 1 < n:
            state = vehicle.step(state, control, dt)
    arr = {k: np.asarray(v, dtype=float) for k, v in rows.items()}
    quat = arr["q"][:, [3, 0, 1, 2]]  # RotorPy xyzw -> quadsim wxyz
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    quat = np.where(quat[:, :1] < 0, -quat, quat)
    t = np.arange(n) * dt
    vbat = np.full(n, nominal_voltage(params))    # RotorPy has no battery model
    return FlightLog(t, arr["x"], quat, arr["v"], arr["gyro"], arr["accel"], arr["rotor"],
                     arr["cmd"] / params.max_speed, vbat, None)
