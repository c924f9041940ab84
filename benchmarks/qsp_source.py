"""Flights of an independent simulator source the project had never used: quad_sim_python
(``quad_sim_python`` 0.0.2 on the package index, pure Python; John Bass's "bobzwik"
Quadcopter_SimCon packaged by R. de Azambuja), its rigid-body equations, its motor dynamics,
drag and wind, its PX4-like cascade controller and its minimum-snap trajectory generator.

What is quad_sim_python's own: the plant (``quad_sim_python.quad.Quadcopter``: 21 states --
NED position, quaternion body (FRD) -> world scalar-first, velocity, body rates, per motor its
speed and speed rate -- the PyDy-derived equations of ``state_dot`` integrated by scipy's
``ode`` dopri5 over each ``update(t, Ts, cmd, wind)`` with the speed commands held), the
rotor forces (thrust ``kTh w^2`` along body -z and reaction ``kTo w^2`` about it, at
(+-dxm, +-dym)), the motor dynamics (a critically damped second order of each speed on its
command, time constant ``tau``, ``damp`` 1, gain ``kp`` 1; speeds clipped to minWmotor..
maxWmotor in the forces), the drag (``Cd sign(u) u^2`` per WORLD axis on the air velocity u,
at the CoM), the wind (``[speed, heading, elevation]``, radians in its equations), the
vehicle (``quad_params``: mB 1.2 kg, IB diag(0.0123, 0.0123, 0.0224) kg m^2, dxm = dym =
0.16 m, kTh 1.076e-5 N s^2/rad^2, kTo 1.632e-7 N m s^2/rad^2, Cd 0.1 N/(m/s)^2, tau 15 ms,
speeds 75..925 rad/s, g 9.81, precession off), its controller (``ctrl.Controller`` with its
``ctrl_params``, position -> velocity -> thrust vector -> attitude -> rate, its ``mixerFM``;
given a nominal plant's parameters: it knows only the nominal values) and its trajectory
generator (``trajectory.Trajectory``, "xyz_pos", minimum snap through timed waypoints,
``yaw_waypoint_interp``).

What is this project's: the waypoints (:func:`path`, the Drake source's loop sampled every
:data:`WAYPOINT_DT` s, blended in from the start point over the first :data:`RAMP` s of the
lead-in; its generator makes the setpoints), the frame conversion (NED/FRD ->
world z up, body x forward, y left, z up: a half turn about x, :func:`_to_ours`), the control
and log rate (500 Hz; its own scripts use 200 Hz), the propeller radius (:data:`ROTOR_RADIUS`:
quad_sim_python has none), the case handles that need a patch of its equations
(:class:`_Plant`: the per-rotor ``kTh``/``kTo`` as arrays in its ``thrust = kTh w^2`` lines,
the CoM's moment of the total thrust, the out-of-library periodic torque and body-z force
added to its ``state_dot``) and the log conversion (:mod:`.simlog`'s shared sensor noise).

Case changes (:data:`EFFECTS`, SI; what of its parameters each sets): ``mass`` (mB),
``payload`` (mB, the CoM, IB's diagonal: its equations use only the principal moments),
``com`` (x, y m: its rotors' arms measured from the moved CoM, dxm -+ x, dym -+ y: its moment
terms plus -c x T), ``inertia`` (relative change of IB's diagonal), ``weak_rotor`` and
``thrust_scale`` (per-rotor factors on kTh and kTo), ``motor_slow`` (factor on tau),
``drag_scale`` (factor on Cd), ``wind`` (m/s world x, y -> its speed and heading),
``torque`` at ``torque_hz`` (N m body), ``force`` at ``force_hz`` (N body z).

Its code as it is, two changes to make it run here, none to its physics: its constructor
hands scipy's dopri5 its tolerances as strings ('0.00005', '10e-6'), which scipy 1.17 refuses
("must be real number"): :class:`_Plant` sets the same integrator with the same numbers;
its ``update(t, Ts, ...)`` integrates up to its first argument (``ode.integrate(t, t + Ts)``:
the second is scipy's ``step`` flag, which dopri5 ignores), so the loop passes the step's
end time. Kept as it is: its yaw row's gyroscopic term (Ixx - Izz) p q / Izz, where Euler's
equations have (Ixx - Iyy) p q (= 0 for its Ixx = Iyy): -0.45 p q rad/s^2 in every flight.

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the control rate): per control step k the
plant after ``update(t_k, Ts, cmd_k, wind)``: its state (CoM), its clipped motor speeds
(``wMotor``, the speeds its forces see), its own state derivative at that state under cmd_k
(``state_dot``: acceleration and angular acceleration, not differenced states), cmd_k /
maxWmotor; converted to our frames and moved to the rotors' centre
(:func:`.simlog.body_origin_log`) with the other sources' sensor noise.

Example::

    >>> log, truth = qsp_flights([FlightSpec(seed=1, effects={"mass": 0.05})])[0]
"""

from __future__ import annotations

import copy
import importlib.util
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log

__all__ = ["CONTROL_HZ", "EFFECTS", "LEAD_IN", "LOG_HZ", "ROTOR_RADIUS", "WAYPOINT_DT",
           "FlightSpec", "fly_one", "hover_speed", "make_plant", "path", "qsp_available",
           "qsp_flights", "qsp_params", "to_flight_log", "vehicle_params"]

#: the controller's rate = the plant's update step (Hz); the log's rate
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the generator's start from rest and the integrals settle)
LEAD_IN = 3.0
#: s between the waypoints handed to its minimum-snap generator (the loop's fastest term,
#: 7.3 x 0.9 x 1.5 rad/s, has a 0.64 s period: >= 6 waypoints a period)
WAYPOINT_DT = 0.1
#: s of waypoints past the logged end (its generator brings the vehicle to rest at the last)
TAIL = 1.0
#: s over which the waypoints blend from the start point into the loop (quintic smoothstep,
#: inside the unlogged lead-in): its generator starts at rest, and the loop's speed within its
#: first 0.1 s segment lost a 2.2x slower motor at 0.67 s (the first --generate-only)
RAMP = 2.0
#: m: a 10-inch propeller (0.127 m): quad_sim_python has no propeller size; the F450-class
#: frame its 1.2 kg and 0.16 m arms describe flies 10-inch propellers (this project's choice)
ROTOR_RADIUS = 0.127
#: case-side changes (module doc)
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "drag_scale", "wind", "torque", "torque_hz", "force", "force_hz")
#: body FLU <-> FRD and world (x, y, z up) <-> NED: a half turn about x (its own inverse)
FLIP = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side changes (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def qsp_available() -> bool:
    """quad_sim_python importable (checked without importing it)."""
    return importlib.util.find_spec("quad_sim_python") is not None


def qsp_params() -> dict:
    """A deep copy of quad_sim_python's ``quad.quad_params`` (its vehicle; the module's dict
    is mutated by every ``Quadcopter``, so each plant gets its own copy)."""
    if not qsp_available():
        raise ModelError("quad_sim_python is not installed "
                         "(pip install --no-deps quad_sim_python==0.0.2)")
    from quad_sim_python.quad import quad_params

    return copy.deepcopy({k: v for k, v in quad_params.items()
                          if k not in ("mixerFM", "mixerFMinv", "FF", "w_hover",
                                       "thr_hover")})


def hover_speed(mass: float | None = None) -> float:
    """Rotor speed (rad/s) at which four nominal rotors carry ``mass`` (kg; default its mB):
    sqrt(m g / (4 kTh)), its own ``init_cmd``."""
    p = qsp_params()
    m = p["mB"] if mass is None else mass
    return float(np.sqrt(m * p["g"] / 4.0 / p["kTh"]))


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of quad_sim_python's vehicle: ``quad_params``' values, not
    fitted. Rotors in its numbering (1 front left, then clockwise seen from above), at
    (dxm, dym), (dxm, -dym), (-dxm, -dym), (-dxm, dym) in body x forward, y left; its yaw row
    (reaction +kTo w^2 of rotors 1, 3 along world up) makes rotors 1, 3 clockwise (quadsim
    spin -1) and 2, 4 counter-clockwise (+1); the command map linear, speed command /
    maxWmotor; no rotor dynamics and no drag (quadsim's nominal model has neither: the shared
    effects of :mod:`.qsp_cases` carry them)."""
    p = qsp_params()
    src = "quad_sim_python 0.0.2 quad.quad_params"
    dx, dy = p["dxm"], p["dym"]
    places = ((dx, dy), (dx, -dy), (-dx, -dy), (-dx, dy))
    rotors = tuple(Rotor(str(k + 1), np.array([x, y, 0.0]), np.array([0.0, 0.0, 1.0]), s)
                   for k, ((x, y), s) in enumerate(zip(places, (-1.0, 1.0, -1.0, 1.0))))
    top = float(p["maxWmotor"])
    params = VehicleParams(
        name="quad-sim-python-quadcopter", mass=p["mB"], com=np.zeros(3),
        inertia=np.asarray(p["IB"], dtype=float), rotors=rotors, thrust_factor=p["kTh"],
        drag_factor=p["kTo"], max_speed=top, min_speed=float(p["minWmotor"]), gravity=p["g"],
        rotor_radius=ROTOR_RADIUS,
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, top]] * 4),
                           "command = speed command / maxWmotor"),
        description="quad_sim_python's quad_params (bobzwik's Quadcopter_SimCon) as quadsim "
                    "sees it",
        sources={"mass": f"{src}['mB']", "inertia": f"{src}['IB']",
                 "rotors": f"{src}['dxm'], ['dym'], makeMixerFM (numbering, yaw row)",
                 "thrust_factor": f"{src}['kTh']", "drag_factor": f"{src}['kTo']",
                 "max_speed": f"{src}['maxWmotor']", "min_speed": f"{src}['minWmotor']",
                 "rotor_radius": "this project's: a 10-inch propeller (none in the source)",
                 "gravity": f"{src}['g']"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> dict:
    """Points of a wandering loop (world x, y, z up): ``pos`` (T, 3) m, ``yaw`` (T,) rad:
    the Drake source's loop (:func:`benchmarks.drake_source.path`, copied so that this
    source's code hash covers it): x = 0.7 cos(w t + phi) + 0.15 sin(2.7 w t) + a sin(6.1 w
    t), y = 0.5 sin(w t + phi) + 0.2 sin(1.9 w t + phi) + a sin(7.3 w t + phi), z = 1.5 + 0.2
    sin(1.3 w t) + 0.05 sin(3.7 w t), yaw = 0.5 sin(0.8 w t), a = 0.03 m / max(speed, 0.5)^2,
    w = 0.9 speed rad/s, phase phi from the seed. Here they are waypoints of its generator."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.03 / max(speed, 0.5) ** 2
    terms = ((0, 0.7, w, phi + np.pi / 2), (0, 0.15, 2.7 * w, 0.0), (0, weave, 6.1 * w, 0.0),
             (1, 0.5, w, phi), (1, 0.2, 1.9 * w, phi), (1, weave, 7.3 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 3.7 * w, 0.0))
    pos = np.zeros((len(t), 3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        pos[:, column] += amp * np.sin(freq * t + phase)
    return {"pos": pos, "yaw": 0.5 * np.sin(0.8 * w * t)}


# ----------------------------------------------------------------------------- the plant


def _job(spec: FlightSpec) -> dict:
    """The flight's changes in SI (module doc): mass, com (3,) body FLU, J (3, 3), rotor
    scale (4,), tau s, Cd, and :func:`benchmarks.flightjobs.disturbances`' loads."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown quad_sim_python effect(s) {sorted(unknown)}; "
                         f"valid: {EFFECTS}")
    p = qsp_params()
    mass, com, inertia = mass_properties(e, p["mB"], np.diag(p["IB"]))
    return {"mass": mass, "com": com, "J": inertia, "rotor_scale": rotor_scales(e),
            "tau": p["tau"] * float(e.get("motor_slow", 1.0)),
            "Cd": p["Cd"] * float(e.get("drag_scale", 1.0)), **disturbances(e)}


def _wind_input(wind: np.ndarray) -> list:
    """Its wind input [speed m/s, heading rad, elevation rad] of a horizontal world wind
    (x, y(, z)) m/s in our frame (NED: (x, -y))."""
    return [float(np.hypot(wind[0], wind[1])), float(np.arctan2(-wind[1], wind[0])), 0.0]


def _plant_class():
    """:class:`_Plant` (built on first use: quad_sim_python imported lazily)."""
    from quad_sim_python.quad import Quadcopter

    class _Plant(Quadcopter):
        """Its ``Quadcopter`` (NED) with this project's minimal patches: per-rotor kTh and
        kTo arrays (set after its own constructor, whose mixer and hover command need
        scalars: the arrays enter only its ``thrust = kTh w^2`` lines), and on top of its
        ``state_dot``: the moment of the total thrust about a CoM at ``com`` (FRD: (-cy T,
        -cx T, 0) for our (cx, cy)) and the loads of the job (body torque, body-z force),
        each divided by its principal moment / its mass."""

        def __init__(self, params: dict, init_states: list, job: dict):
            self.job = job
            super().__init__(0.0, init_states, orient="NED", params=params)
            from scipy.integrate import ode

            # its own integrator and tolerances as numbers (its constructor passes the
            # strings '0.00005', '10e-6': scipy >= 1.x refuses them, "must be real number")
            self.integrator = ode(self.state_dot).set_integrator(
                "dopri5", first_step=0.00005, atol=10e-6, rtol=10e-6)
            self.integrator.set_initial_value(self.state, 0.0)
            scale = np.asarray(job["rotor_scale"], dtype=float)
            self.params["kTh"] = params["kTh"] * scale
            self.params["kTo"] = params["kTo"] * scale
            self.forces()

        def state_dot(self, t, state, cmd, wind):
            sdot = super().state_dot(t, state, cmd, wind)
            job, p = self.job, self.params
            w = np.clip(state[[13, 15, 17, 19]], p["minWmotor"], p["maxWmotor"])
            total = float(np.sum(p["kTh"] * w * w))
            c = job["com"]
            torque = np.array([-c[1] * total, -c[0] * total, 0.0])
            torque += FLIP @ (np.asarray(job["torque"], dtype=float)
                              * np.sin(2 * np.pi * job["torque_hz"] * t))
            sdot[10:13] += torque / np.diag(p["IB"])
            force = job["force"] * np.sin(2 * np.pi * job["force_hz"] * t)
            if force != 0.0:
                q0, q1, q2, q3 = state[3:7]
                body_z = np.array([2 * (q1 * q3 + q0 * q2), 2 * (q2 * q3 - q0 * q1),
                                   q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3])   # R[:, 2]
                sdot[7:10] += -force * body_z / p["mB"]        # our body +z = FRD -z
            return sdot

    return _Plant


def make_plant(job: dict, position=(0.0, 0.0, 0.0), yaw: float = 0.0):
    """quad_sim_python's plant of one flight (NED) with the job's mB, IB, tau, Cd, per-rotor
    kTh/kTo factors, CoM and loads (``job`` as :func:`_job` makes it), at rest at
    ``position`` (NED m) and heading ``yaw`` (rad, NED), its motors at its hover speed of the
    job's mass."""
    p = qsp_params()
    p.update(mB=float(job["mass"]), IB=np.asarray(job["J"], dtype=float),
             tau=float(job["tau"]), Cd=float(job["Cd"]))
    x, y, z = (float(v) for v in position)
    return _plant_class()(p, [x, y, z, 0.0, 0.0, float(yaw), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                          job)


def nominal_job() -> dict:
    """The job of a flight with no change."""
    return _job(FlightSpec(seed=0))


# ----------------------------------------------------------------------------- flying


def _to_ours(vec: np.ndarray) -> np.ndarray:
    """(N, 3) vectors NED/FRD -> world z up / body FLU (x, -y, -z)."""
    return np.asarray(vec) @ FLIP


def fly_one(args: tuple) -> dict:
    """One flight ``(spec, job)`` (top level: run in worker processes): the lead-in plus the
    logged samples at :data:`CONTROL_HZ` (module doc); (T, ...) arrays in our frames pos,
    vel (world, CoM), quat (wxyz body -> world), ang_vel, ang_acc (body), acc (world, with
    gravity), rotor, cmd (rad/s). Its ``Trajectory`` (minimum snap through the loop's
    waypoints, blended in over :data:`RAMP` s, yaw interpolated) and its ``Controller`` with
    its gains on a nominal plant's parameters read the true state. A flight that leaves
    control (tilt past 60 deg, below 0.05 m, non-finite) raises ModelError."""
    from quad_sim_python.ctrl import Controller, ctrl_params
    from quad_sim_python.trajectory import Trajectory

    spec, job = args
    dt = 1.0 / CONTROL_HZ
    lead = round(LEAD_IN * CONTROL_HZ)
    n = round(spec.duration * CONTROL_HZ)
    t_wp = np.arange(0.0, (lead + n) * dt + TAIL + WAYPOINT_DT / 2, WAYPOINT_DT)
    loop, start = path(t_wp, spec.seed, spec.speed), path(t_wp[:1], spec.seed, spec.speed)
    x = np.clip(t_wp / RAMP, 0.0, 1.0)
    blend = x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)                  # 0 -> 1, C2
    wps = _to_ours(start["pos"] + blend[:, None] * (loop["pos"] - start["pos"]))   # NED
    yaws = -(start["yaw"] + blend * (loop["yaw"] - start["yaw"]))
    plant = make_plant(job, wps[0], yaws[0])
    nominal = make_plant(nominal_job(), wps[0], yaws[0])
    ctrl = Controller(nominal.params, orient="NED", params=copy.deepcopy(ctrl_params))
    traj = Trajectory(yaws[0], "xyz_pos", [6, "yaw_waypoint_interp", 0],
                      (t_wp, wps, yaws, 0.0))
    wind = _wind_input(job["wind"])
    out = {k: np.zeros((n, 4 if k in ("quat", "rotor", "cmd") else 3))
           for k in ("pos", "vel", "quat", "ang_vel", "ang_acc", "acc", "rotor", "cmd")}
    lo, hi = plant.params["minWmotor"], plant.params["maxWmotor"]
    for k in range(lead + n):
        t = k * dt
        s = traj.desiredState(plant.pos, t, dt)
        ctrl.control(dt, "xyz_pos", "yaw_waypoint_interp", s[0:3], s[3:6], s[6:9], s[9:12],
                     s[14], s[18], plant.pos, plant.vel, plant.vel_dot, plant.quat,
                     plant.omega, plant.omega_dot, plant.psi)
        cmd = ctrl.getMotorSpeeds()
        plant.update(t + dt, dt, cmd, wind)          # integrates up to its first argument
        x = plant.state
        q = x[3:7] / np.linalg.norm(x[3:7])
        tilt = q[0] ** 2 - q[1] ** 2 - q[2] ** 2 + q[3] ** 2           # R[2, 2]
        if not np.all(np.isfinite(x)) or tilt < 0.5 or -x[2] < 0.05:
            raise ModelError(f"quad_sim_python flight (seed {spec.seed}) lost control at "
                             f"t = {(k + 1) * dt - LEAD_IN:.3f} s")
        if k >= lead:
            i = k - lead
            d = plant.state_dot(t + dt, x, cmd, wind)
            out["pos"][i], out["vel"][i] = x[0:3], x[7:10]
            out["quat"][i] = x[3:7] * np.array([1.0, 1.0, -1.0, -1.0])
            out["ang_vel"][i], out["ang_acc"][i] = x[10:13], d[10:13]
            out["acc"][i] = d[7:10]
            out["rotor"][i] = np.clip(x[[13, 15, 17, 19]], lo, hi)
            out["cmd"][i] = cmd
    for key in ("pos", "vel", "ang_vel", "ang_acc", "acc"):
        out[key] = _to_ours(out[key])
    return out


def qsp_flights(specs: list[FlightSpec], workers: int | None = None
                ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (in ``workers`` processes, :func:`benchmarks.flightjobs.fly_all`) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's changes in SI, seed, speed)."""
    if not qsp_available():
        raise ModelError("quad_sim_python is not installed "
                         "(pip install --no-deps quad_sim_python==0.0.2)")
    jobs = [_job(s) for s in specs]
    return fly_all(fly_one, to_flight_log, specs, jobs, source="quad-sim-python",
                   model="Quadcopter", rates=(CONTROL_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com=None) -> FlightLog:
    """:func:`fly_one`'s samples (of the CoM, our frames) -> a quadsim :class:`FlightLog` of
    the rotors' centre (``com`` (3,) m body: the CoM relative to it) with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``)."""
    p = qsp_params()
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"], quat=raw["quat"],
                       ang_vel=raw["ang_vel"], ang_acc=raw["ang_acc"], acc=raw["acc"],
                       rotor_speed=raw["rotor"], command=raw["cmd"] / p["maxWmotor"])
    return body_origin_log(states, np.zeros(3) if com is None else np.asarray(com, float),
                           spec.sensors, spec.seed, hover_speed=hover_speed(),
                           gravity=p["g"])
