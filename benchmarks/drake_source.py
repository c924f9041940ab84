"""Flights of an independent simulator source the project had never used: Drake (Toyota
Research Institute, ``drake`` 1.51.1 on the package index, BSD-3), its multibody engine and
the quadrotor of its examples (``pydrake.examples.QuadrotorPlant``, the Skydio 2 values).

What is Drake's own: the rigid body (``MultibodyPlant``, continuous, a floating body with its
mass, CoM and inertia: a CoM off the body origin and a payload's full inertia are Drake's
mass properties, not an added torque), the rotor forces (``Propeller``: per rotor a force
``thrust_ratio x command`` along its axis and a moment ``moment_ratio x command`` about it,
at the rotor's place on the body), the sum of the applied forces
(``ExternallyAppliedSpatialForceMultiplexer``), the rotor state (``SymbolicVectorSystem``),
the integrator (Drake's ``Simulator`` with its default error-controlled RK3, target
accuracy :data:`ACCURACY`), the vehicle (``QuadrotorPlant()``'s m 0.775 kg, arm L 0.15 m,
inertia diag(0.0015, 0.0025, 0.0035) kg m^2, kF 1, kM 0.0245 m: rotors at (L, 0), (0, L),
(-L, 0), (0, -L), the 1st and 3rd with moment +kM per N) and the controller's gains
(Drake's ``LinearQuadraticRegulator`` on ``Linearize(QuadrotorPlant)`` at hover).

What is this project's: the rotor speed (Drake's command is the thrust in N, kF = 1; the
speed is sqrt(thrust / b) with b = 6.11e-8 N/RPM^2, Mellinger, Michael and Kumar's
Hummingbird value whose kM / kF is Drake's 0.0245: 5.57e-6 N s^2/rad^2, hover 584 rad/s);
its propeller radius (:data:`ROTOR_RADIUS`, the same vehicle's); the rotor limits (thrust
per rotor 0.05-2.25 x the hover thrust); no rotor dynamics in the nominal vehicle (Drake's
has none: the speed is the command held over the 2 ms step); an aerodynamic drag Drake does
not model (:class:`_Loads`: a linear drag on the air velocity in body axes, -m
diag(:data:`DRAG_RATE`) v, applied at the body origin), the case handles, the controller's
law around Drake's gains (:class:`Controller`) and the log conversion (:mod:`.simlog`'s
shared sensor noise).

Case changes (:data:`EFFECTS`, SI): ``mass``, ``payload`` (point mass: mass, CoM and the
full inertia, Drake's ``SpatialInertia``), ``com`` (x, y m: the body's CoM off the rotors'
centre), ``inertia`` (relative change of Jxx, Jyy, Jzz), ``weak_rotor`` and
``thrust_scale`` (factors on the propellers' thrust and moment ratios), ``motor_tau`` (s: a
first-order lag of each rotor speed on its command), ``drag_scale`` (factor on the drag),
``wind`` (m/s world x, y: the drag on the air velocity), ``rate_damping`` (-k w, body),
``torque`` at ``torque_hz`` (periodic body torque), ``force`` at ``force_hz`` (periodic
body-z force), ``rotor_delay`` (the rotor-speed log only, s late).

The log (:func:`to_flight_log`, :data:`LOG_HZ` = the control rate): the body origin (the
rotors' centre: Drake's floating body state is its origin's), its attitude, world velocity,
body rates, the specific force and angular acceleration from the plant's generalised
acceleration at each sample (the command of that sample applied), the rotor speed and the
command (speed command / :func:`max_speed`), with the other sources' sensor noise.

Example::

    >>> log, truth = drake_flights([FlightSpec(seed=1, effects={"mass": 0.05})])[0]
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log

__all__ = ["ACCURACY", "B_PER_RPM2", "CONTROL_HZ", "DRAG_RATE", "EFFECTS", "LEAD_IN", "LOG_HZ",
           "ROTOR_RADIUS", "THRUST_RANGE", "Controller", "FlightSpec", "build", "drake_available",
           "drake_flights", "drake_params", "fly_one", "hover_speed", "max_speed", "path",
           "thrust_factor", "to_flight_log", "vehicle_params"]

#: the controller's rate, the command held between (Hz); the log's rate
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the integrals settle)
LEAD_IN = 3.0
#: Drake's Simulator target accuracy (its RK3's error control; Drake's default 1e-4 at 1e-6
#: changes a flight's positions by < 1e-6 m)
ACCURACY = 1e-6
#: N/RPM^2: the Hummingbird's kF (Mellinger, Michael, Kumar 2012), Drake's kM / kF 0.0245
#: is its kM / kF (1.5e-9 / 6.11e-8)
B_PER_RPM2 = 6.11e-8
#: m: the Hummingbird's 8-inch propellers (the kF above is theirs; this project's: Drake has
#: no propeller size)
ROTOR_RADIUS = 0.1016
#: per-rotor thrust range as multiples of the nominal hover thrust (this project's)
THRUST_RANGE = (0.05, 2.25)
#: 1/s: the linear drag per unit mass on the body x, y, z air velocity (this project's: the
#: rotor drag of small quadrotors, 0.3-0.5 /s in the plane, little along the axis)
DRAG_RATE = (0.3, 0.3, 0.1)
#: case-side changes (module doc)
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_tau",
           "drag_scale", "wind", "rate_damping", "torque", "torque_hz", "force", "force_hz",
           "rotor_delay")


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side changes (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def drake_available() -> bool:
    """pydrake importable (checked without importing it)."""
    return importlib.util.find_spec("pydrake") is not None


def drake_params() -> dict:
    """Drake's quadrotor values (``QuadrotorPlant()``): m kg, g m/s^2, L m, I (3, 3) kg m^2,
    kF (N per unit command), kM (N m per unit command)."""
    if not drake_available():
        raise ModelError("Drake is not installed (pip install -e '.[drake]')")
    from pydrake.examples import QuadrotorPlant

    q = QuadrotorPlant()
    return {"m": float(q.m()), "g": float(q.g()), "L": float(q.length()),
            "I": np.array(q.inertia(), dtype=float), "kF": float(q.force_constant()),
            "kM": float(q.moment_constant())}


def thrust_factor() -> float:
    """b (N s^2/rad^2) of :data:`B_PER_RPM2`."""
    return B_PER_RPM2 * (60.0 / (2.0 * np.pi)) ** 2


def hover_speed(mass: float | None = None) -> float:
    """Rotor speed (rad/s) at which four nominal rotors carry ``mass`` (kg; default Drake's)."""
    p = drake_params()
    m = p["m"] if mass is None else mass
    return float(np.sqrt(m * p["g"] / 4.0 / thrust_factor()))


def max_speed() -> float:
    """Rotor speed (rad/s) at the top of :data:`THRUST_RANGE` (the command's full scale)."""
    return hover_speed() * float(np.sqrt(THRUST_RANGE[1]))


#: rotor k of QuadrotorPlant: (x, y) in units of L and its moment sign (+kM per N)
LAYOUT = (((1, 0), 1.0), ((0, 1), -1.0), ((-1, 0), 1.0), ((0, -1), -1.0))


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of Drake's quadrotor: ``QuadrotorPlant()``'s values, not
    fitted; b from :data:`B_PER_RPM2`, d = kM b; rotor k at :data:`LAYOUT`, spin -sign (a
    moment +kM along +z is the reaction of a clockwise rotor); speed range from
    :data:`THRUST_RANGE`; the command map linear, speed command / :func:`max_speed`."""
    p = drake_params()
    b = thrust_factor()
    src = "drake 1.51.1 pydrake.examples.QuadrotorPlant()"
    rotors = tuple(Rotor(str(k + 1), np.array([x * p["L"], y * p["L"], 0.0]),
                         np.array([0.0, 0.0, 1.0]), -sign)
                   for k, ((x, y), sign) in enumerate(LAYOUT))
    top = max_speed()
    params = VehicleParams(
        name="drake-quadrotor", mass=p["m"], com=np.zeros(3), inertia=p["I"], rotors=rotors,
        thrust_factor=b, drag_factor=p["kM"] * b, max_speed=top,
        min_speed=hover_speed() * float(np.sqrt(THRUST_RANGE[0])), gravity=p["g"],
        rotor_radius=ROTOR_RADIUS,
        motor_map=MotorMap("1", np.array([0.0, 1.0]), np.array([[0.0, top]] * 4),
                           "command = speed command / the speed at the top thrust"),
        description="Drake's QuadrotorPlant (Skydio 2 values) as quadsim sees it",
        sources={"mass": f"{src}.m()", "inertia": f"{src}.inertia()",
                 "rotors": f"{src}.length() and its layout (quadrotor_plant.cc)",
                 "thrust_factor": "6.11e-8 N/RPM^2 (Mellinger et al. 2012; this project's)",
                 "drag_factor": f"{src}.moment_constant() 0.0245 m x b",
                 "max_speed": f"{THRUST_RANGE[1]} x the hover thrust (this project's)",
                 "min_speed": f"{THRUST_RANGE[0]} x the hover thrust (this project's)",
                 "rotor_radius": "8-inch propellers of the kF's vehicle (this project's)",
                 "gravity": f"{src}.g()"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> dict:
    """Setpoints of a wandering loop: ``pos``, ``vel``, ``acc`` (T, 3) (m, m/s, m/s^2),
    ``yaw``, ``yaw_rate`` (T,) (rad, rad/s). x = 0.7 cos(w t + phi) + 0.15 sin(2.7 w t) + a
    sin(6.1 w t), y = 0.5 sin(w t + phi) + 0.2 sin(1.9 w t + phi) + a sin(7.3 w t + phi), z =
    1.5 + 0.2 sin(1.3 w t) + 0.05 sin(3.7 w t), yaw = 0.5 sin(0.8 w t), a = 0.03 m /
    max(speed, 0.5)^2 (a weave of about 0.9 m/s^2 at every speed: roll and pitch excitation),
    w = 0.9 speed rad/s, phase phi from the seed (the drone-models source's loop, 0.5 m
    higher, a stronger weave)."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.03 / max(speed, 0.5) ** 2
    terms = ((0, 0.7, w, phi + np.pi / 2), (0, 0.15, 2.7 * w, 0.0), (0, weave, 6.1 * w, 0.0),
             (1, 0.5, w, phi), (1, 0.2, 1.9 * w, phi), (1, weave, 7.3 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 3.7 * w, 0.0))
    pos, vel, acc = np.zeros((len(t), 3)), np.zeros((len(t), 3)), np.zeros((len(t), 3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        arg = freq * t + phase
        pos[:, column] += amp * np.sin(arg)
        vel[:, column] += amp * freq * np.cos(arg)
        acc[:, column] -= amp * freq ** 2 * np.sin(arg)
    return {"pos": pos, "vel": vel, "acc": acc, "yaw": 0.5 * np.sin(0.8 * w * t),
            "yaw_rate": 0.5 * 0.8 * w * np.cos(0.8 * w * t)}


# ----------------------------------------------------------------------------- the diagram


def _job(spec: FlightSpec) -> dict:
    """The flight's changes in SI (module doc)."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown Drake effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    p = drake_params()
    mass, com, inertia = mass_properties(e, p["m"], np.diag(p["I"]))
    return {"mass": mass, "com": com, "J": inertia, "rotor_scale": rotor_scales(e),
            "motor_tau": float(e.get("motor_tau", 0.0)),
            "drag_scale": float(e.get("drag_scale", 1.0)), **disturbances(e)}


def _loads_class():
    """The :class:`_Loads` LeafSystem class (built on first use: pydrake imported lazily)."""
    from pydrake.common.value import AbstractValue
    from pydrake.multibody.math import SpatialForce
    from pydrake.multibody.plant import ExternallyAppliedSpatialForce_
    from pydrake.systems.framework import LeafSystem

    force_type = ExternallyAppliedSpatialForce_[float]

    class _Loads(LeafSystem):
        """This project's loads on the body (Drake has no aerodynamics): input the plant's
        state (qw qx qy qz x y z, w_W, v_W); output one spatial force at the body origin,
        world frame: the drag -R D R^T (v - wind), the periodic body-z force, the rate
        damping -k w_B and the periodic body torque (both rotated to the world)."""

        def __init__(self, body_index, job: dict):
            super().__init__()
            self.body = body_index
            self.drag = job["drag"]
            self.wind = np.asarray(job["wind"], dtype=float)
            self.damping = np.asarray(job["rate_damping"], dtype=float)
            self.force, self.force_hz = float(job["force"]), float(job["force_hz"])
            self.torque, self.torque_hz = (np.asarray(job["torque"], dtype=float),
                                           float(job["torque_hz"]))
            self.DeclareVectorInputPort("state", 13)
            self.DeclareAbstractOutputPort("forces", lambda: AbstractValue.Make([force_type()]),
                                           self._calc)

        def _calc(self, context, output):
            x = self.get_input_port(0).Eval(context)
            t = context.get_time()
            rot = _rotmat(x[0:4])
            air = rot.T @ (x[10:13] - self.wind)
            body_f = -self.drag @ air
            body_f[2] += self.force * np.sin(2 * np.pi * self.force_hz * t)
            body_t = (-self.damping * (rot.T @ x[7:10])
                      + self.torque * np.sin(2 * np.pi * self.torque_hz * t))
            f = force_type()
            f.body_index = self.body
            f.p_BoBq_B = np.zeros(3)
            f.F_Bq_W = SpatialForce(rot @ body_t, rot @ body_f)
            output.set_value([f])

    return _Loads


def _rotmat(q) -> np.ndarray:
    """Body -> world rotation of a scalar-first quaternion (normalised here)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@dataclass
class Flight:
    """A built Drake diagram: the simulator, its plant, body, rotor system and contexts."""

    diagram: object
    simulator: object
    plant: object
    body: object
    rotors: object
    context: object
    plant_context: object
    rotor_context: object
    lagged: bool


def build(job: dict) -> Flight:
    """The Drake diagram of one flight (module doc): ``job`` as :func:`_job` makes it, plus
    ``drag`` (3, 3) N/(m/s) body. Its one input is the four rotor speed commands (rad/s)."""
    from pydrake.math import RigidTransform
    from pydrake.multibody.plant import (
        ExternallyAppliedSpatialForceMultiplexer,
        MultibodyPlant,
        Propeller,
        PropellerInfo,
    )
    from pydrake.multibody.tree import RotationalInertia, SpatialInertia
    from pydrake.symbolic import MakeVectorVariable
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import Demultiplexer, SymbolicVectorSystem

    p = drake_params()
    b = thrust_factor()
    builder = DiagramBuilder()
    plant = builder.AddSystem(MultibodyPlant(0.0))
    J = np.asarray(job["J"], dtype=float)
    inertia = RotationalInertia(J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2])
    body = plant.AddRigidBody("quadrotor", SpatialInertia.MakeFromCentralInertia(
        float(job["mass"]), np.asarray(job["com"], dtype=float), inertia))
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, -p["g"]])
    plant.Finalize()
    scale = np.asarray(job["rotor_scale"], dtype=float)
    infos = [PropellerInfo(body.index(), RigidTransform([x * p["L"], y * p["L"], 0.0]),
                           b * p["kF"] * s, sign * p["kM"] * b * s)
             for ((x, y), sign), s in zip(LAYOUT, scale)]
    propellers = builder.AddSystem(Propeller(infos))
    loads = builder.AddSystem(_loads_class()(body.index(), job))
    mux = builder.AddSystem(ExternallyAppliedSpatialForceMultiplexer(2))
    u = MakeVectorVariable(4, "u")
    tau = float(job["motor_tau"])
    with np.errstate(invalid="ignore"):     # numpy's checks on arrays of symbolic terms
        if tau > 0:                         # rotor speed: first-order lag on the command
            w = MakeVectorVariable(4, "w")
            rotors = SymbolicVectorSystem(state=w, dynamics=(u - w) / tau, input=u,
                                          output=np.concatenate([w * w, w]))
        else:                               # the speed is the command (a dummy state)
            z = MakeVectorVariable(1, "z")
            rotors = SymbolicVectorSystem(state=z, dynamics=[0.0 * z[0]], input=u,
                                          output=np.concatenate([u * u, u]))
    rotors = builder.AddSystem(rotors)
    demux = builder.AddSystem(Demultiplexer([4, 4]))
    builder.Connect(rotors.get_output_port(), demux.get_input_port())
    builder.Connect(demux.get_output_port(0), propellers.get_command_input_port())
    builder.Connect(plant.get_body_poses_output_port(), propellers.get_body_poses_input_port())
    builder.Connect(plant.get_state_output_port(), loads.get_input_port(0))
    builder.Connect(propellers.get_spatial_forces_output_port(), mux.get_input_port(0))
    builder.Connect(loads.get_output_port(0), mux.get_input_port(1))
    builder.Connect(mux.get_output_port(), plant.get_applied_spatial_force_input_port())
    builder.ExportInput(rotors.get_input_port(), "speed_command")
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.get_mutable_integrator().set_target_accuracy(ACCURACY)
    context = simulator.get_mutable_context()
    return Flight(diagram, simulator, plant, body, rotors, context,
                  plant.GetMyContextFromRoot(context), rotors.GetMyContextFromRoot(context),
                  tau > 0)


# ----------------------------------------------------------------------------- the controller


class Controller:
    """LQR about hover with Drake's gains (this project's law around them): Drake's
    ``LinearQuadraticRegulator`` on ``Linearize(QuadrotorPlant)`` (state: position, roll
    pitch yaw, their rates; input: the four rotor thrusts, N) augmented with the integrals of
    the position and yaw errors, weights :data:`Q` and :data:`R`. Each step: the errors in the
    path's yaw frame (the gains are for yaw 0), roll and pitch setpoints from the path's
    acceleration, the thrust m |a + g| / 4 fed forward, thrust = feed forward - K e, clipped
    to :data:`THRUST_RANGE`, to speed commands through the nominal b. Knows only the nominal
    values; reads the true state."""

    #: weights: position (m^-2), roll/pitch/yaw (rad^-2), velocity, rates, integrals
    Q = (30.0, 30.0, 30.0, 20.0, 20.0, 10.0, 6.0, 6.0, 6.0, 0.5, 0.5, 0.5, 8.0, 8.0, 8.0, 2.0)
    #: per rotor thrust (N^-2)
    R = 1.0
    #: integral limit (m, rad)
    I_MAX = 1.0

    def __init__(self, dt: float):
        from pydrake.examples import QuadrotorPlant
        from pydrake.systems.controllers import LinearQuadraticRegulator
        from pydrake.systems.primitives import Linearize

        p = drake_params()
        self.p, self.dt, self.b = p, dt, thrust_factor()
        quad = QuadrotorPlant()
        ctx = quad.CreateDefaultContext()
        ctx.SetContinuousState(np.zeros(12))
        quad.get_input_port(0).FixValue(ctx, np.full(4, p["m"] * p["g"] / 4))
        lin = Linearize(quad, ctx)
        a = np.zeros((16, 16))
        a[:12, :12] = lin.A()
        a[12:15, 0:3] = np.eye(3)
        a[15, 5] = 1.0
        bb = np.zeros((16, 4))
        bb[:12] = lin.B()
        self.K, _ = LinearQuadraticRegulator(a, bb, np.diag(self.Q), self.R * np.eye(4))
        self.integral = np.zeros(4)
        hover = p["m"] * p["g"] / 4
        self.limits = THRUST_RANGE[0] * hover, THRUST_RANGE[1] * hover

    def step(self, rot: np.ndarray, pos, vel, w_world, sp: dict) -> np.ndarray:
        """Rotor speed commands (4,) rad/s at body -> world ``rot`` (3, 3), position,
        velocity (world), angular velocity (world), setpoints ``sp`` (pos, vel, acc (3,);
        yaw, yaw_rate)."""
        from pydrake.math import RollPitchYaw, RotationMatrix

        rpy = RollPitchYaw(RotationMatrix(rot))
        rates = rpy.CalcRpyDtFromAngularVelocityInParent(w_world)
        psi = sp["yaw"]
        c, s = np.cos(psi), np.sin(psi)
        to_path = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        up = sp["acc"] + np.array([0.0, 0.0, self.p["g"]])
        ah = to_path @ up
        pitch_sp = np.arctan2(ah[0], ah[2])
        roll_sp = np.arctan2(-ah[1], np.hypot(ah[0], ah[2]))
        yaw_err = (rpy.yaw_angle() - psi + np.pi) % (2 * np.pi) - np.pi
        e_pos = to_path @ (pos - sp["pos"])
        self.integral = np.clip(self.integral + np.append(e_pos, yaw_err) * self.dt,
                                -self.I_MAX, self.I_MAX)
        err = np.concatenate([e_pos, [rpy.roll_angle() - roll_sp, rpy.pitch_angle() - pitch_sp,
                                      yaw_err], to_path @ (vel - sp["vel"]),
                              rates - np.array([0.0, 0.0, sp["yaw_rate"]]), self.integral])
        thrust = self.p["m"] * np.linalg.norm(up) / 4 - self.K @ err
        return np.sqrt(np.clip(thrust, *self.limits) / self.b)


# ----------------------------------------------------------------------------- flying


def fly_one(args: tuple) -> dict:
    """One flight ``(spec, job)`` (top level: run in worker processes): the lead-in plus the
    logged samples at :data:`CONTROL_HZ`, each the state at t_k with the command of t_k and
    the plant's acceleration under it; (T, ...) arrays pos, vel (world, body origin), quat
    (wxyz body -> world), ang_vel, ang_acc (body), acc (world), rotor, cmd (rad/s). A flight
    that leaves control (tilt past 60 deg, below 0.05 m, non-finite) raises ModelError."""
    from pydrake.math import RigidTransform, RollPitchYaw
    from pydrake.multibody.math import SpatialVelocity

    spec, job = args
    p = drake_params()
    job = {**job, "drag": job["drag_scale"] * p["m"] * np.diag(DRAG_RATE)}
    flight = build(job)
    lead = round(LEAD_IN * CONTROL_HZ)
    n = round(spec.duration * CONTROL_HZ)
    dt = 1.0 / CONTROL_HZ
    t = np.arange(lead + n) * dt
    sp_all = path(t, spec.seed, spec.speed)
    start = RigidTransform(RollPitchYaw(0.0, 0.0, sp_all["yaw"][0]), sp_all["pos"][0])
    flight.plant.SetFreeBodyPose(flight.plant_context, flight.body, start)
    flight.plant.SetFreeBodySpatialVelocity(flight.plant_context, flight.body,
                                            SpatialVelocity(np.zeros(3), sp_all["vel"][0]))
    speed0 = hover_speed(job["mass"] / float(np.mean(job["rotor_scale"])))
    if flight.lagged:
        flight.rotor_context.SetContinuousState(np.full(4, speed0))
    ctrl = Controller(dt)
    port = flight.diagram.get_input_port(0)
    out = {k: np.zeros((n, 4 if k in ("quat", "rotor", "cmd") else 3))
           for k in ("pos", "vel", "quat", "ang_vel", "ang_acc", "acc", "rotor", "cmd")}
    acc_port = flight.plant.get_generalized_acceleration_output_port()
    for k in range(lead + n):
        x = flight.plant.GetPositionsAndVelocities(flight.plant_context)
        rot = _rotmat(x[0:4])
        tilt = rot[2, 2]
        if not np.all(np.isfinite(x)) or tilt < 0.5 or x[6] < 0.05:
            raise ModelError(f"Drake flight (seed {spec.seed}) lost control at t = "
                             f"{k * dt - LEAD_IN:.3f} s")
        sp = {key: value[k] for key, value in sp_all.items()}
        cmd = ctrl.step(rot, x[4:7], x[10:13], x[7:10], sp)
        port.FixValue(flight.context, cmd)
        if k >= lead:
            i = k - lead
            vdot = acc_port.Eval(flight.plant_context)
            rotor = (flight.rotor_context.get_continuous_state_vector().CopyToVector()
                     if flight.lagged else cmd)
            out["pos"][i], out["vel"][i], out["quat"][i] = x[4:7], x[10:13], x[0:4]
            out["ang_vel"][i] = rot.T @ x[7:10]
            out["ang_acc"][i] = rot.T @ vdot[0:3]
            out["acc"][i] = vdot[3:6]
            out["rotor"][i], out["cmd"][i] = rotor, cmd
        flight.simulator.AdvanceTo((k + 1) * dt)
    return out


def drake_flights(specs: list[FlightSpec], workers: int | None = None
                  ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (in ``workers`` processes, :func:`benchmarks.flightjobs.fly_all`) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's changes in SI, seed, speed)."""
    if not drake_available():
        raise ModelError("Drake is not installed (pip install -e '.[drake]')")
    jobs = [_job(s) for s in specs]
    return fly_all(fly_one, to_flight_log, specs, jobs, source="drake",
                   model="QuadrotorPlant", rates=(CONTROL_HZ, LOG_HZ), workers=workers)


def to_flight_log(raw: dict, spec: FlightSpec, com=None) -> FlightLog:
    """:func:`fly_one`'s samples -> a quadsim :class:`FlightLog` with the sensor model of
    ``spec.sensors`` (seeded by ``spec.seed``; the rotor log ``rotor_delay`` s late when the
    spec asks). ``com`` is not used: Drake's state is already the body origin's."""
    p = drake_params()
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"], quat=raw["quat"],
                       ang_vel=raw["ang_vel"], ang_acc=raw["ang_acc"], acc=raw["acc"],
                       rotor_speed=raw["rotor"], command=raw["cmd"] / max_speed())
    return body_origin_log(states, np.zeros(3), spec.sensors, spec.seed,
                           hover_speed=hover_speed(),
                           rotor_delay=float(spec.effects.get("rotor_delay", 0.0)),
                           gravity=p["g"])
