"""Flights of an independent simulator source the project had never used: JSBSim 1.3.3
(``jsbsim`` on the package index, a compiled flight-dynamics model; PX4's SITL flies it
through px4-jsbsim-bridge) and the DJI F450 quadcopter its wheel ships
(``jsbsim/aircraft/F450``).

What is JSBSim's own: the plant (its 6-DOF equations on a rotating WGS84 Earth with J2
gravity, its integrators at their defaults), its atmosphere, the F450's files as shipped
(Mass.xml 1.4 kg, J diag(0.0190, 0.0190, 0.0252) kg m^2 about the CG at the structural
origin; Propulsion.xml four ``DJI_E305`` brushless motors driving ``DJI_9450`` propellers at
(+-0.1651, +-0.1651, 0.025) m, senses +1 front right and aft left, -1 the others; Aero.xml a
drag C_D 1.0 on 0.016129 m^2, no other coefficient; Effectors.xml the ESC commands
``fcs/throttle-pos-norm[i]``), the motor (``FGBrushLessDCMotor``: Kv 960 rpm/V, R 0.117 ohm,
I0 0.45 A, 14.63 V; its speed from its own torque balance against the propeller's torque
and inertia 6.05e-5 kg m^2: steady speed where Kv (V c - R I) = rpm, I = Kv_SI Q + I0; a lag
of about 55 ms at hover), the propeller (``FGPropeller``: thrust C_T(J) rho n^2 D^4, torque
C_P(J) rho n^2 D^5 / 2 pi, J the advance ratio of the air speed along its axis; the body gets
the motor's torque, the aerodynamic one plus the rotor's spin-up, and the rotors' gyroscopic
moments), its handles for every case (below) and its wind.

What is this project's: the controller (:class:`benchmarks.geometric.Geometric`, the
Genesis and quadcopter-sim sources' geometric tracking controller, tuned on the nominal
parameter set, its rotor speeds turned into throttles by :func:`throttle_for`, the motor's
steady map from the engine file; the F450's own FlightControl.xml is a rate loop for a
pilot and cannot fly a path: it is bypassed through its ``fcs/cmd??_ext_nd`` inputs with
its pilot commands at zero and ``fcs/ScasEngage`` 0), the start (airborne at
:data:`HEIGHT` m above the initGrnd.xml field, held by JSBSim's ``forces/hold-down`` for
:data:`HOLD` s at the nominal hover throttle while the rotors spin up from rest, then
released), the path (the Drake source's loop, :func:`path`, heading north), the frame
conversion (NED / body FRD in feet -> SI, world x north, y west, z up, body FLU: a half turn
about x) and the additions a case needs that the F450 files lack: a rate damping (a moment
-k p per axis written into Aero.xml) and the out-of-library loads (JSBSim's own
``external_reactions``: a body moment or force whose magnitude this module sets per step).

The parameter set (:func:`vehicle_params`, read off the files as a user would): mass, CG,
inertia from Mass.xml; the rotor places from Propulsion.xml (structural frame x aft, y
right, z up -> FLU about the CG); spins from the senses (+1: counter-clockwise seen from
above, found by spinning up rotors 1 and 2: the body yaws clockwise); b = C_T(0) rho D^4 /
4 pi^2 and d = C_P(0) rho D^5 / 8 pi^3 from the propeller's tables at zero advance ratio (a
hover) with the ISA density at the field's height (:data:`RHO`); the rotor inertia the
propeller file's Ixx; the command map the motor's steady speed per throttle (Kv, R, I0,
14.63 V and d); gravity the WGS84 normal gravity at the field (:data:`GRAVITY`); never
fitted on a flight.

Case changes (:data:`EFFECTS`, SI) and the handle each sets: ``mass`` (kg: a Mass.xml
pointmass at the CG), ``payload`` (kg, x, y, z m FLU: a pointmass there; JSBSim moves the CG
and adds its parallel-axis inertia), ``com`` (x, y m FLU: Mass.xml's CG location),
``inertia`` (relative change of Mass.xml's ixx, iyy, izz), ``weak_rotor`` (rotor 1..4,
relative change) and ``thrust_scale`` (relative change of all four) (the propeller's
C_THRUST table scaled in a copy of DJI_9450 for that rotor: its speed untouched, its torque
table kept), ``motor_slow`` (factor on every propeller's Ixx in DJI_9450: the motor's time
constant J / (k_t k_e / R + 2 d Omega) scales with it, and so do the rotors' spin-up and
gyroscopic moments), ``rate_damping`` (N m s/rad x, y, z: Aero.xml moment functions, this project's
addition), ``wind`` (m/s world x, y: ``atmosphere/wind-north-fps``, ``wind-east-fps``),
``torque`` (N m body x, y, z amplitude) at ``torque_hz`` and ``force`` (N body z amplitude)
at ``force_hz`` (``external_reactions``).

The log (:func:`to_flight_log`, :data:`LOG_HZ`): JSBSim runs its Propagate model first, so
after ``run()`` the state is the new one and the forces and accelerations are those of that
state; the rotor speeds that made them are the ones read before ``run()`` (the propeller
updates its speed after its thrust); their throttle the one of the step before. Per step:
position (geodetic -> local metres about the start), NED velocity, the Euler angles, body
rates, ``accelerations/p,q,rdot``, the specific force (``forces/fb?-total-lbs`` / mass: the
accelerometer's; the world acceleration written as R f + g so that the log's accelerometer is
JSBSim's own), the rotor speeds (``propulsion/engine[i]/propeller-rpm``), the throttles;
converted to our frames and moved to the rotors' centre (the structural origin, the nominal
CG; :func:`.simlog.body_origin_log`) with the other sources' sensor noise.

Example::

    >>> log, truth = jsbsim_flights([FlightSpec(seed=1, effects={"mass": 0.1})])[0]
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadsim.core.errors import ModelError
from quadsim.logs.flightlog import FlightLog
from quadsim.vehicle.params import MotorMap, Rotor, VehicleParams, check_physical

from .flightjobs import disturbances, fly_all, mass_properties, rotor_scales
from .simlog import Sensors, SimStates, body_origin_log

__all__ = ["ARM", "CD_AREA", "CONTROL_HZ", "C_POWER0", "C_THRUST0", "DIAMETER", "EFFECTS",
           "GRAVITY", "HEIGHT", "INERTIA", "LEAD_IN", "LOG_HZ", "MASS", "PROP_INERTIA",
           "RHO", "ROTOR_Z", "FlightSpec", "drag_factor", "fly_one", "hover_speed",
           "jsbsim_available", "jsbsim_flights", "make_job", "motor_time_constant",
           "open_fdm", "path", "read_state",
           "steady_speed", "throttle_for", "thrust_factor", "to_flight_log",
           "vehicle_params", "write_aircraft"]

#: the controller's and the log's rate = JSBSim's step (Hz)
CONTROL_HZ = 500
LOG_HZ = 500
#: s flown before the log starts (the hold, the path's blend from rest, the loops settle)
LEAD_IN = 3.0
#: s held by forces/hold-down at the nominal hover throttle while the rotors spin up
HOLD = 0.5
#: s over which the path blends from its start point into the loop (after the hold)
RAMP = 2.0
#: m above the field the path's z = 0 lies (the gear, 0.15 m below the CG, never touches)
HEIGHT = 20.0
#: initGrnd.xml's field: deg, deg, m above sea level
LATITUDE, LONGITUDE, ELEVATION = 44.725801, -93.075866, 285.2111
#: Mass.xml: kg, kg m^2 (about the CG, the structural origin)
MASS = 1.4
INERTIA = np.diag([0.0190, 0.0190, 0.0252])
#: Propulsion.xml: m, the rotors' offsets along x and y; m, their height above the CG
ARM = 0.1651
ROTOR_Z = 0.025
#: Propulsion.xml: engines 0..3 (front right, aft left, front left, aft right) and senses
ENGINES = ("FR", "AL", "FL", "AR")
SENSES = (1.0, 1.0, -1.0, -1.0)
#: DJI_9450.xml: m (9.4 in), C_THRUST and C_POWER at J = 0, kg m^2
DIAMETER = 9.4 * 0.0254
C_THRUST0 = 0.1288
C_POWER0 = 0.0666
PROP_INERTIA = 6.05e-5
#: DJI_E305.xml: rpm/V, ohm, A, V
KV_RPM, COIL_R, NO_LOAD_I, MAX_VOLTS = 960.0, 0.117, 0.45, 14.63
#: Aero.xml / Metrics.xml: C_D 1.0 on 0.016129 m^2 (m^2)
CD_AREA = 1.0 * 0.016129
#: m: the path's mean height above the field plus HEIGHT: where b and d take the density
FLIGHT_ALT = ELEVATION + HEIGHT + 1.5
#: kg/m^3: ISA density at FLIGHT_ALT (1.225 (1 - 2.25577e-5 h)^4.25588)
RHO = 1.225 * (1.0 - 2.25577e-5 * FLIGHT_ALT) ** 4.25588
#: m/s^2: WGS84 normal gravity (Somigliana) at the field's latitude, less the free-air
#: gradient 3.086e-6 /s^2 x FLIGHT_ALT (what a user takes for the local g)
GRAVITY = float(9.7803253359 * (1 + 0.00193185265241 * np.sin(np.radians(LATITUDE)) ** 2)
                / np.sqrt(1 - 0.00669437999013 * np.sin(np.radians(LATITUDE)) ** 2)
                - 3.086e-6 * FLIGHT_ALT)
#: case-side changes (module doc)
EFFECTS = ("mass", "payload", "com", "inertia", "weak_rotor", "thrust_scale", "motor_slow",
           "rate_damping", "wind", "torque", "torque_hz", "force", "force_hz")
#: body FLU <-> FRD and world (x north, y west, z up) <-> NED: a half turn about x
FLIP = np.diag([1.0, -1.0, -1.0])
FT, LBF, SLUG = 0.3048, 4.4482216152605, 14.593902937
#: rad/s per V: Kv in SI
KV = KV_RPM * 2 * np.pi / 60.0


@dataclass(frozen=True)
class FlightSpec:
    """One flight: seed (path phase, sensor noise), speed factor of the path, duration (s,
    logged), case-side changes (:data:`EFFECTS`)."""

    seed: int
    speed: float = 1.0
    duration: float = 8.0
    effects: dict = field(default_factory=dict)
    sensors: Sensors = field(default_factory=Sensors)


def jsbsim_available() -> bool:
    """jsbsim importable (checked without importing it)."""
    return importlib.util.find_spec("jsbsim") is not None


def _require() -> None:
    if not jsbsim_available():
        raise ModelError("jsbsim is not installed (pip install jsbsim==1.3.3)")


def motor_time_constant(slow: float = 1.0) -> float:
    """s: the motor's lag linearised at the hover speed, J slow / (k_t k_e / R + 2 d W)
    (k_t = k_e = 1 / Kv SI; 54.8 ms nominal)."""
    return float(PROP_INERTIA * slow / (1.0 / (KV * KV * COIL_R)
                                       + 2 * drag_factor() * hover_speed()))


def thrust_factor() -> float:
    """b (N s^2/rad^2): C_T(0) rho D^4 / (4 pi^2), the propeller's hover thrust per squared
    speed (n = Omega / 2 pi rev/s)."""
    return float(C_THRUST0 * RHO * DIAMETER ** 4 / (4 * np.pi ** 2))


def drag_factor() -> float:
    """d (N m s^2/rad^2): C_P(0) rho D^5 / (8 pi^3), its torque P / Omega per squared speed."""
    return float(C_POWER0 * RHO * DIAMETER ** 5 / (8 * np.pi ** 3))


def hover_speed(mass: float = MASS) -> float:
    """Rotor speed (rad/s) at which four nominal rotors carry ``mass`` (kg): sqrt(m g / 4 b)."""
    return float(np.sqrt(mass * GRAVITY / 4.0 / thrust_factor()))


def throttle_for(speed) -> np.ndarray:
    """The throttle (0..1) whose steady speed is ``speed`` (rad/s) with the nominal
    propeller at J = 0: (Omega / Kv + R (Kv d Omega^2 + I0)) / 14.63 V (the engine file's
    three constants; the current is the propeller's torque d Omega^2 times Kv in SI)."""
    w = np.asarray(speed, dtype=float)
    volts = w / KV + COIL_R * (KV * drag_factor() * w * w + NO_LOAD_I)
    return np.clip(volts / MAX_VOLTS, 0.0, 1.0)


def steady_speed(throttle) -> np.ndarray:
    """:func:`throttle_for`'s inverse (rad/s, 0 below the no-load current's voltage)."""
    c = np.asarray(throttle, dtype=float)
    a, b = COIL_R * KV * drag_factor(), 1.0 / KV
    rest = COIL_R * NO_LOAD_I - MAX_VOLTS * c
    return np.maximum((-b + np.sqrt(np.maximum(b * b - 4 * a * rest, 0.0))) / (2 * a), 0.0)


def _rotor_places() -> np.ndarray:
    """(4, 3) m FLU about the CG: Propulsion.xml's structural (x aft, y right, z up) places of
    engines 0..3 turned (-x, -y, z)."""
    xs = np.array([[-ARM, ARM], [ARM, -ARM], [-ARM, -ARM], [ARM, ARM]])
    return np.column_stack([-xs[:, 0], -xs[:, 1], np.full(4, ROTOR_Z)])


def vehicle_params() -> VehicleParams:
    """quadsim's parameter set of the F450 (module doc), not fitted: rotors 1..4 = engines 0..3
    (front right, aft left, front left, aft right) at (+-0.1651, +-0.1651, 0.025) m FLU, spins
    +1, +1, -1, -1; the command map the motor's steady speed at 21 throttles."""
    grid = np.linspace(0.0, 1.0, 21)
    rotors = tuple(Rotor(str(k + 1), p, np.array([0.0, 0.0, 1.0]), s)
                   for k, (p, s) in enumerate(zip(_rotor_places(), SENSES)))
    src = "JSBSim 1.3.3 aircraft/F450"
    params = VehicleParams(
        name="jsbsim-f450", mass=MASS, com=np.zeros(3), inertia=INERTIA.copy(),
        rotors=rotors, thrust_factor=thrust_factor(), drag_factor=drag_factor(),
        max_speed=float(steady_speed(1.0)), min_speed=0.0, rotor_radius=DIAMETER / 2,
        rotor_inertia=PROP_INERTIA, gravity=GRAVITY, air_density=RHO,
        motor_map=MotorMap("1", grid, np.tile(steady_speed(grid), (4, 1)),
                           "DJI_E305 steady speed per throttle with DJI_9450 at J = 0"),
        description="JSBSim's F450 (its aircraft files) as quadsim sees it",
        sources={"mass": f"{src}/Mass.xml emptywt", "inertia": f"{src}/Mass.xml ixx iyy izz",
                 "rotors": f"{src}/Propulsion.xml locations and senses",
                 "thrust_factor": "DJI_9450.xml C_THRUST(0) rho D^4 / 4 pi^2, ISA rho",
                 "drag_factor": "DJI_9450.xml C_POWER(0) rho D^5 / 8 pi^3, ISA rho",
                 "max_speed": "DJI_E305.xml steady speed at throttle 1",
                 "rotor_radius": "DJI_9450.xml diameter / 2",
                 "rotor_inertia": "DJI_9450.xml ixx",
                 "gravity": "WGS84 normal gravity at initGrnd.xml's latitude",
                 "air_density": "ISA at the flight altitude"})
    check_physical(params, where=params.name)
    return params


# ----------------------------------------------------------------------------- the path


def path(t: np.ndarray, seed: int, speed: float) -> dict:
    """The Drake source's wandering loop (:func:`benchmarks.pm_source.path`, copied so that
    this source's code hash covers it; world x north, y west, z up): ``pos`` (T, 3) m and its
    exact time derivatives ``vel`` (T, 3) m/s and ``acc`` (T, 3) m/s^2."""
    phi = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    w = 0.9 * speed
    weave = 0.03 / max(speed, 0.5) ** 2
    terms = ((0, 0.7, w, phi + np.pi / 2), (0, 0.15, 2.7 * w, 0.0), (0, weave, 6.1 * w, 0.0),
             (1, 0.5, w, phi), (1, 0.2, 1.9 * w, phi), (1, weave, 7.3 * w, phi),
             (2, 0.2, 1.3 * w, 0.0), (2, 0.05, 3.7 * w, 0.0))
    t = np.asarray(t, dtype=float)
    pos, vel, acc = (np.zeros((len(t), 3)) for _ in range(3))
    pos[:, 2] = 1.5
    for column, amp, freq, phase in terms:
        pos[:, column] += amp * np.sin(freq * t + phase)
        vel[:, column] += amp * freq * np.cos(freq * t + phase)
        acc[:, column] -= amp * freq * freq * np.sin(freq * t + phase)
    return {"pos": pos, "vel": vel, "acc": acc}


def _setpoint(t: float, seed: int, speed: float) -> tuple[np.ndarray, ...]:
    """(p, v, a) world at ``t`` s after the hold: the loop blended in from its start point
    over :data:`RAMP` s (quintic smoothstep s: p = p0 + s (L - p0), v = s' (L - p0) + s L',
    a = s'' (L - p0) + 2 s' L' + s L'')."""
    now, start = path(np.array([t]), seed, speed), path(np.zeros(1), seed, speed)
    x = min(max(t / RAMP, 0.0), 1.0)
    s = x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)
    ds = 30.0 * x * x * (1.0 - x) ** 2 / RAMP
    dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / RAMP ** 2
    delta = now["pos"][0] - start["pos"][0]
    return (start["pos"][0] + s * delta, ds * delta + s * now["vel"][0],
            dds * delta + 2 * ds * now["vel"][0] + s * now["acc"][0])


# ----------------------------------------------------------------------------- the plant


def make_job(spec: FlightSpec) -> dict:
    """The flight's changes in SI (module doc): mass, com (3,) body FLU, J (3, 3) FLU (what
    JSBSim computes from its pointmasses: :func:`benchmarks.flightjobs.mass_properties`),
    the pointmass (kg and FLU place; () for none), the CG's (x, y) FLU, thrust (4,) factors on
    each rotor's C_THRUST table, slow (the factor on every propeller's spin inertia), and
    :func:`benchmarks.flightjobs.disturbances`' loads."""
    e = dict(spec.effects)
    unknown = set(e) - set(EFFECTS)
    if unknown:
        raise ValueError(f"unknown jsbsim effect(s) {sorted(unknown)}; valid: {EFFECTS}")
    mass, com, inertia = mass_properties(e, MASS, np.diag(INERTIA))
    point: tuple = ()
    if "mass" in e:
        point = (float(e["mass"]), float(e.get("com", (0, 0))[0]),
                 float(e.get("com", (0, 0))[1]), 0.0)
    if "payload" in e:
        point = tuple(float(v) for v in e["payload"])
    cg = tuple(float(v) for v in e.get("com", (0.0, 0.0)))
    return {"mass": mass, "com": com, "J": inertia, "pointmass": point, "cg": cg,
            "inertia_scale": tuple(1.0 + np.asarray(e.get("inertia", (0, 0, 0)), float)),
            "thrust": rotor_scales(e), "slow": float(e.get("motor_slow", 1.0)),
            **disturbances(e)}


def _xyz(parent: ET.Element, tag: str, flu, unit: str = "M", name: str | None = None):
    """A <location> or <direction> child in JSBSim's structural axes (x aft, y right, z up)
    of a FLU vector."""
    el = ET.SubElement(parent, tag, {"unit": unit} if name is None else
                       {"name": name, "unit": unit})
    for axis, v in zip("xyz", (-flu[0], -flu[1], flu[2])):
        ET.SubElement(el, axis).text = f" {float(v):.12g} "
    return el


def _frd(parent: ET.Element, flu) -> None:
    """A <direction> child in body axes (an external reaction's frame BODY: x forward, y
    right, z down) of a FLU vector."""
    el = ET.SubElement(parent, "direction")
    for axis, v in zip("xyz", FLIP @ np.asarray(flu, dtype=float)):
        ET.SubElement(el, axis).text = f" {float(v):.12g} "


def write_aircraft(root: Path, job: dict) -> None:
    """The F450 of ``job`` under ``root``: JSBSim's files copied (aircraft/F450, engine, a
    link to systems) with the job's handles written in (module doc)."""
    import jsbsim

    home = Path(jsbsim.get_default_root_dir())
    craft = root / "aircraft" / "F450"
    shutil.copytree(home / "aircraft" / "F450", craft)
    (root / "engine").mkdir()
    for name in ("DJI_E305.xml", "DJI_9450.xml"):
        shutil.copy(home / "engine" / name, root / "engine" / name)
    os.symlink(home / "systems", root / "systems")
    mass = ET.parse(craft / "Mass.xml")
    top = mass.getroot()
    cg = top.find("location")
    cg.find("x").text, cg.find("y").text = f" {-job['cg'][0]:.12g} ", f" {-job['cg'][1]:.12g} "
    for axis, scale in zip(("ixx", "iyy", "izz"), job["inertia_scale"]):
        el = top.find(axis)
        el.text = f" {float(el.text) * scale:.12g} "
    if job["pointmass"]:
        m, *place = job["pointmass"]
        point = ET.SubElement(top, "pointmass", {"name": "case"})
        ET.SubElement(point, "weight", {"unit": "KG"}).text = f" {m:.12g} "
        _xyz(point, "location", place, name="POINTMASS")
    mass.write(craft / "Mass.xml")
    prop = ET.parse(craft / "Propulsion.xml")
    for k, (engine, scale) in enumerate(zip(prop.getroot().iter("engine"), job["thrust"])):
        if scale != 1.0 or job["slow"] != 1.0:
            name = f"DJI_9450_{k}"
            table = ET.parse(home / "engine" / "DJI_9450.xml")
            ixx = table.getroot().find("ixx")
            ixx.text = f" {float(ixx.text) * job['slow']:.12g} "
            for t in table.getroot().iter("table"):
                if t.get("name") == "C_THRUST":
                    data = t.find("tableData")
                    rows = [r.split() for r in data.text.strip().splitlines()]
                    data.text = "\n" + "\n".join(f"{r[0]} {float(r[1]) * scale:.12g}"
                                                 for r in rows) + "\n"
            table.write(root / "engine" / f"{name}.xml")
            engine.find("thruster").set("file", name)
    prop.write(craft / "Propulsion.xml")
    aero = ET.parse(craft / "Aero.xml")
    axes = {a.get("name"): a for a in aero.getroot().iter("axis")}
    for axis, rate, k in zip(("ROLL", "PITCH", "YAW"), "pqr", job["rate_damping"]):
        if k:
            fn = ET.SubElement(axes[axis], "function", {"name": f"aero/moment/{axis}_damping"})
            product = ET.SubElement(fn, "product")
            ET.SubElement(product, "value").text = f" {-float(k) / (LBF * FT):.12g} "
            ET.SubElement(product, "property").text = f"velocities/{rate}-rad_sec"
    aero.write(craft / "Aero.xml")
    if np.any(job["torque"]) or job["force"]:
        main = ET.parse(craft / "F450.xml")
        ext = ET.SubElement(main.getroot(), "external_reactions")
        if np.any(job["torque"]):
            moment = ET.SubElement(ext, "moment", {"name": "tug", "frame": "BODY",
                                                   "unit": "LBSFT"})
            _frd(moment, job["torque"] / np.linalg.norm(job["torque"]))
        if job["force"]:
            force = ET.SubElement(ext, "force", {"name": "push", "frame": "BODY",
                                                 "unit": "LBS"})
            _xyz(force, "location", (0.0, 0.0, 0.0))
            _frd(force, (0.0, 0.0, 1.0))
        main.write(craft / "F450.xml")


@contextlib.contextmanager
def _quiet():
    """JSBSim's loader prints to the C streams: send fd 1 and 2 to /dev/null meanwhile."""
    saved = [os.dup(1), os.dup(2)]
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def open_fdm(root: Path, job: dict, position=(0.0, 0.0, 1.5)):
    """JSBSim's FGFDMExec of the F450 under ``root`` at :data:`CONTROL_HZ`, level, heading
    north, at rest at ``position`` (world m about the field's point, z above HEIGHT), its
    engines running, its FCS bypassed (module doc), the job's wind set."""
    import jsbsim

    with _quiet():
        fdm = jsbsim.FGFDMExec(root_dir=str(root))
        fdm.set_debug_level(0)
        fdm.load_model("F450")
    fdm.set_dt(1.0 / CONTROL_HZ)
    lat, lon = _latlon(np.asarray(position, float))
    fdm["ic/lat-geod-deg"], fdm["ic/long-gc-deg"] = lat, lon
    fdm["ic/terrain-elevation-ft"] = ELEVATION / FT
    fdm["ic/h-agl-ft"] = (HEIGHT + position[2]) / FT
    for k in ("phi", "theta", "psi"):
        fdm[f"ic/{k}-deg"] = 0.0
    for k in ("u", "v", "w"):
        fdm[f"ic/{k}-fps"] = 0.0
    with _quiet():
        fdm.run_ic()
    fdm["fcs/throttle-cmd-norm"] = 0.0
    fdm["fcs/ScasEngage"] = 0.0
    for i in range(4):
        fdm[f"propulsion/engine[{i}]/set-running"] = 1
    fdm["atmosphere/wind-north-fps"] = job["wind"][0] / FT
    fdm["atmosphere/wind-east-fps"] = -job["wind"][1] / FT
    return fdm


def _radii() -> tuple[float, float]:
    """(meridian, prime-vertical) WGS84 radii of curvature at the field (m)."""
    a, e2 = 6378137.0, 0.00669437999014
    s2 = np.sin(np.radians(LATITUDE)) ** 2
    return a * (1 - e2) / (1 - e2 * s2) ** 1.5, a / np.sqrt(1 - e2 * s2)


def _latlon(pos: np.ndarray) -> tuple[float, float]:
    """(geodetic latitude, longitude) deg of world (x north, y west) m about the field."""
    m, n = _radii()
    h = ELEVATION + HEIGHT
    return (LATITUDE + np.degrees(pos[0] / (m + h)),
            LONGITUDE - np.degrees(pos[1] / ((n + h) * np.cos(np.radians(LATITUDE)))))


def read_state(fdm) -> dict:
    """The CG's state in our frames (SI): pos (world x north, y west, z up above HEIGHT),
    vel, rot (body FLU -> world), ang_vel, ang_acc (body FLU), force (specific force, body
    FLU, m/s^2), rotor (rad/s), mass (kg)."""
    m, n = _radii()
    h = fdm["position/h-sl-meters"]
    lat, lon = fdm["position/lat-geod-rad"], fdm["position/long-gc-rad"]
    north = (lat - np.radians(LATITUDE)) * (m + h)
    east = (lon - np.radians(LONGITUDE)) * (n + h) * np.cos(np.radians(LATITUDE))
    pos = np.array([north, -east, h - ELEVATION - HEIGHT])
    vel = FLIP @ np.array([fdm["velocities/v-north-fps"], fdm["velocities/v-east-fps"],
                           fdm["velocities/v-down-fps"]]) * FT
    phi, theta, psi = (fdm[f"attitude/{k}-rad"] for k in ("phi", "theta", "psi"))
    cr, sr, cp, sp, cy, sy = (np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta),
                              np.cos(psi), np.sin(psi))
    rot_ned = np.array([[cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
                        [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
                        [-sp, sr * cp, cr * cp]])
    rates = np.array([fdm[f"velocities/{k}-rad_sec"] for k in "pqr"])
    dots = np.array([fdm[f"accelerations/{k}dot-rad_sec2"] for k in "pqr"])
    slugs = fdm["inertia/mass-slugs"]
    force = np.array([fdm[f"forces/fb{k}-total-lbs"] for k in "xyz"]) / slugs * FT
    rotor = np.array([fdm[f"propulsion/engine[{i}]/propeller-rpm"] for i in range(4)])
    return {"pos": pos, "vel": vel, "rot": FLIP @ rot_ned @ FLIP, "ang_vel": FLIP @ rates,
            "ang_acc": FLIP @ dots, "force": FLIP @ force, "rotor": rotor * np.pi / 30.0,
            "mass": slugs * SLUG}


def _set_throttles(fdm, throttles) -> None:
    for name, c in zip(ENGINES, throttles):
        fdm[f"fcs/cmd{name}_ext_nd"] = float(c)


def _set_loads(fdm, job: dict, t: float) -> None:
    """The out-of-library loads' magnitudes at ``t`` s (lbs ft, lbs)."""
    if np.any(job["torque"]):
        fdm["external_reactions/tug/magnitude-lbsft"] = (
            float(np.linalg.norm(job["torque"])) * np.sin(2 * np.pi * job["torque_hz"] * t)
            / (LBF * FT))
    if job["force"]:
        fdm["external_reactions/push/magnitude"] = (
            job["force"] * np.sin(2 * np.pi * job["force_hz"] * t) / LBF)


def fly_one(args: tuple) -> dict:
    """One flight ``(spec, job)`` (top level: run in worker processes): the hold, the
    lead-in, then the logged samples at :data:`CONTROL_HZ` (module doc); (T, ...) arrays in
    our frames pos, vel (world, CoM), rot (body -> world), ang_vel, ang_acc (body), acc
    (world, R f + g), rotor (rad/s), command (throttles). A flight that leaves control
    (tilt past 60 deg, below 5 m above the field's path zero, non-finite) raises
    ModelError."""
    from .geometric import Geometric

    spec, job = args
    dt = 1.0 / CONTROL_HZ
    hold, lead = round(HOLD * CONTROL_HZ), round((LEAD_IN - HOLD) * CONTROL_HZ)
    n = round(spec.duration * CONTROL_HZ)
    p0 = _setpoint(0.0, spec.seed, spec.speed)[0]
    out = {k: np.zeros((n, 3)) for k in ("pos", "vel", "ang_vel", "ang_acc", "acc")}
    out["rot"], out["rotor"], out["command"] = np.zeros((n, 3, 3)), np.zeros((n, 4)), \
        np.zeros((n, 4))
    with tempfile.TemporaryDirectory(prefix="quadsim-jsbsim-") as folder:
        write_aircraft(Path(folder), job)
        fdm = open_fdm(Path(folder), job, p0)
        params = vehicle_params()
        control = Geometric(dt, params, throttle_for)
        before = np.full(4, float(throttle_for(hover_speed())))
        fdm["forces/hold-down"] = 1
        _set_throttles(fdm, before)
        for _ in range(hold):
            _set_loads(fdm, job, 0.0)
            fdm.run()
        fdm["forces/hold-down"] = 0
        for k in range(lead + n):
            t = k * dt
            s = read_state(fdm)
            p_d, v_d, a_d = _setpoint(t, spec.seed, spec.speed)
            quat = _rot_to_quat(s["rot"][None])[0]
            command = control.step(s["pos"], s["vel"], quat, s["ang_vel"], p_d, v_d, a_d,
                                   0.0, 0.0)
            _set_throttles(fdm, command)
            _set_loads(fdm, job, t + dt)
            rotor = s["rotor"]
            fdm.run()
            s = read_state(fdm)
            if (not all(np.all(np.isfinite(v)) for v in s.values()) or s["rot"][2, 2] < 0.5
                    or s["pos"][2] < -5.0):
                raise ModelError(f"jsbsim flight (seed {spec.seed}) lost control at "
                                 f"t = {(k + 1) * dt - LEAD_IN + HOLD:.3f} s")
            if k >= lead:
                i = k - lead
                out["pos"][i], out["vel"][i], out["rot"][i] = s["pos"], s["vel"], s["rot"]
                out["ang_vel"][i], out["ang_acc"][i] = s["ang_vel"], s["ang_acc"]
                out["acc"][i] = s["rot"] @ s["force"] - np.array([0.0, 0.0, GRAVITY])
                out["rotor"][i], out["command"][i] = rotor, before
            before = command
    return out


def jsbsim_flights(specs: list[FlightSpec], workers: int | None = None
                   ) -> list[tuple[FlightLog, dict]]:
    """Fly every spec (in ``workers`` processes, :func:`benchmarks.flightjobs.fly_all`) and
    return ``(log, truth)`` per spec: the log as :func:`to_flight_log` makes it, the truth
    sidecar (effects, the flight's changes in SI, seed, speed)."""
    _require()
    jobs = [make_job(s) for s in specs]
    return fly_all(fly_one, to_flight_log, specs, jobs, source="jsbsim",
                   model="F450", rates=(CONTROL_HZ, LOG_HZ), workers=workers)


def _rot_to_quat(rot: np.ndarray) -> np.ndarray:
    """(N, 4) scalar-first unit quaternions (w >= 0) of (N, 3, 3) rotation matrices."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(rot).as_quat()[:, [3, 0, 1, 2]]
    return np.where(q[:, :1] < 0, -q, q)


def to_flight_log(raw: dict, spec: FlightSpec, com=None) -> FlightLog:
    """:func:`fly_one`'s samples (of the CoM, our frames) -> a quadsim :class:`FlightLog` of
    the rotors' centre's projection on the CG plane, the structural origin (``com`` (3,) m
    body: the CoM relative to it) with the sensor model of ``spec.sensors`` (seeded by
    ``spec.seed``)."""
    states = SimStates(rate_hz=LOG_HZ, pos=raw["pos"], vel=raw["vel"],
                       quat=_rot_to_quat(raw["rot"]), ang_vel=raw["ang_vel"],
                       ang_acc=raw["ang_acc"], acc=raw["acc"], rotor_speed=raw["rotor"],
                       command=raw["command"])
    return body_origin_log(states, np.zeros(3) if com is None else np.asarray(com, float),
                           spec.sensors, spec.seed, hover_speed=hover_speed(),
                           gravity=GRAVITY)
