"""Vehicle parameter sets: TOML files in ``models/`` loaded into frozen, validated objects.

A parameter set is everything the two engines need about one vehicle: rigid-body mass
properties, rotor geometry and the rotor factors b (thrust) and d (drag torque). Every stored
number is an inline table ``{ value = ..., unit = "...", source = "..." }`` so that the file
itself says its unit and where the number came from (which table, which fit). The loader
checks the unit string against the one expected for the field; values are SI inside.

Conventions (used throughout quadsim)
-------------------------------------
* World frame: z up. Body frame: x forward, y left, z up; origin at the geometric centre of
  the frame (the point rotor positions are measured from).
* ``com`` is the centre of mass in the body frame (m); ``inertia`` is the 3x3 tensor about
  the CoM in body axes (kg m^2).
* A rotor spinning ``ccw`` turns counter-clockwise about its own thrust axis (seen from the
  tip of the axis, i.e. from above for an upright rotor). Its reaction (drag) torque on the
  body is ``-spin_sign * d * Omega^2`` along the axis, with ``spin_sign = +1`` for ccw.
* Thrust of rotor i: ``b * Omega_i^2`` along its axis (N); Omega in rad/s.

Mass properties may come from the CAD assembly instead of numbers::

    [body]
    from_cad = { path = "../cad", source = "meshes in cad/, trimesh mass properties" }

and the rotor layout likewise (``[rotor_layout] from_cad = {...}``), so that a fact lives in
one place. Example::

    >>> from quadsim.vehicle.params import load_params
    >>> p = load_params("physical")
    >>> p.mass, p.rotor_count
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import InputError, ModelError, field_error
from ..core.files import check_schema, read_toml
from ..core.shipped import shipped_dir

#: Folder holding the built-in parameter sets (``--model NAME``): the repository's
#: ``models/``, or its copy inside an installed wheel (:mod:`quadsim.core.shipped`).
MODELS_DIR = shipped_dir("models")
SCHEMA = "quadsim.vehicle.params/1"
#: earlier names of :data:`SCHEMA`, read with one warning (the content is the same; CHANGELOG)
EARLIER_SCHEMAS = {"quadsim.params/1": "renamed with the package layout, CHANGELOG.md"}

SPIN_SIGN = {"ccw": 1.0, "cw": -1.0}


@dataclass(frozen=True)
class Rotor:
    """One rotor: hub position (m, body frame), unit thrust axis (body frame), spin sign
    (+1 ccw about the axis, -1 cw)."""

    name: str
    position: np.ndarray
    axis: np.ndarray
    spin: float


@dataclass(frozen=True)
class MotorMap:
    """Command -> steady rotor speed, piecewise linear per rotor (saturation included).

    ``command`` (K,) in ``command_unit``; ``speed`` (R, K) in rad/s, at the battery voltage
    ``reference_voltage`` (V) when one is given. Optional, from ``identify --logs``:
    ``voltage_gain`` (1/V): the steady speed scales by ``1 + voltage_gain (v - reference_voltage)``
    (:meth:`speed_at`); ``time_constant`` (s): first-order lag from command to speed.
    ``duty_voltage`` (V; None: not used): the map's command axis is the duty cycle times the
    battery voltage over ``duty_voltage`` (a DC motor's no-load speed is proportional to duty
    x voltage), so ``speed = map(command vbat / duty_voltage)`` (:meth:`speed_at`; the
    held-out diagnosis fits such a map, :func:`quadsim.gap.residual.fit_motor_map`).
    """

    command_unit: str
    command: np.ndarray
    speed: np.ndarray
    source: str
    reference_voltage: float | None = None
    voltage_gain: float = 0.0
    time_constant: float = 0.0
    duty_voltage: float | None = None

    def speed_at(self, command: np.ndarray, voltage: np.ndarray | None) -> np.ndarray:
        """Steady speed (rad/s) for commands (N, R) at battery voltages (N,) (V; None: the
        reference voltage, or ``duty_voltage``)."""
        if self.duty_voltage is not None:
            command = np.asarray(command, float)
            if voltage is not None:
                command = command * (np.asarray(voltage, float) / self.duty_voltage)[..., None]
        speed = self.speed_of(command)
        if voltage is None or self.reference_voltage is None or self.voltage_gain == 0.0:
            return speed
        return speed * (1.0 + self.voltage_gain * (np.asarray(voltage, float)
                                                   - self.reference_voltage))[..., None]

    def speed_of(self, command: np.ndarray) -> np.ndarray:
        """Steady speed (rad/s) for commands of shape (..., R)."""
        command = np.asarray(command, dtype=float)
        out = np.empty_like(command)
        for i in range(self.speed.shape[0]):
            out[..., i] = np.interp(command[..., i], self.command, self.speed[i])
        return out

    def command_of(self, speed: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`speed_of`: the command (..., R) in ``command_unit`` whose steady
        speed is ``speed`` (..., R) (rad/s), per rotor through the same table (each rotor's
        speeds must increase along it; a speed beyond the table's ends gives its end command)."""
        speed = np.asarray(speed, dtype=float)
        out = np.empty_like(speed)
        for i in range(self.speed.shape[0]):
            out[..., i] = np.interp(speed[..., i], self.speed[i], self.command)
        return out

    def command_at(self, speed: np.ndarray, voltage: np.ndarray | None) -> np.ndarray:
        """Inverse of :meth:`speed_at`: the command (N, R) in ``command_unit`` whose steady
        speed at battery voltages ``voltage`` (N,) (V; None: the reference voltage, or
        ``duty_voltage``) is ``speed`` (N, R) (rad/s): the speed divided by the voltage
        law's factor ``1 + voltage_gain (v - reference_voltage)``, through :meth:`command_of`,
        and for a duty-cycle map times ``duty_voltage / v``."""
        speed = np.asarray(speed, dtype=float)
        if not (voltage is None or self.reference_voltage is None or self.voltage_gain == 0.0):
            speed = speed / (1.0 + self.voltage_gain * (np.asarray(voltage, float)
                                                        - self.reference_voltage))[..., None]
        command = self.command_of(speed)
        if self.duty_voltage is not None and voltage is not None:
            command = command * (self.duty_voltage / np.asarray(voltage, float))[..., None]
        return command

    def to_unit(self, command: np.ndarray) -> np.ndarray:
        """Normalised 0-1 commands (a flight log's ``cmd_i``) -> ``command_unit``: the same
        for a map in ``"1"``, else 0-1 spans the table (e.g. PWM 1000-2000)."""
        if self.command_unit == "1":
            return command
        return self.command[0] + command * (self.command[-1] - self.command[0])

    def normalised(self, command: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_unit`: commands in ``command_unit`` -> normalised 0-1."""
        if self.command_unit == "1":
            return command
        return (command - self.command[0]) / (self.command[-1] - self.command[0])


@dataclass(frozen=True)
class VehicleParams:
    """A validated parameter set (SI units). See the module docstring for frames.

    Attributes:
      name: short name (``physical``, ``computational``, ``report``, ...).
      mass: total mass (kg).
      com: centre of mass in the body frame (3,) (m).
      inertia: inertia tensor about the CoM, body axes (3, 3) (kg m^2).
      rotors: rotor geometry, in the numbering of the parameter set.
      thrust_factor: b, thrust per squared speed (N s^2 / rad^2).
      drag_factor: d, reaction torque per squared speed (N m s^2 / rad^2).
      max_speed / min_speed: rotor speed range (rad/s).
      rotor_radius: propeller radius (m).
      rotor_inertia: spin inertia of rotor + motor bell about its axis (kg m^2).
      gravity: (m/s^2), air_density: (kg/m^3).
      motor_map: optional command -> speed map.
      sources: field name -> source text, for every stored number.
      path: the file the set was loaded from (None if built in code).
      cad_dir: the CAD folder the mass properties or rotor layout come from (``from_cad``).
    """

    name: str
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    rotors: tuple[Rotor, ...]
    thrust_factor: float
    drag_factor: float
    max_speed: float
    min_speed: float = 0.0
    rotor_radius: float = 0.0
    rotor_inertia: float = 0.0
    gravity: float = 9.81
    air_density: float = 1.225
    motor_map: MotorMap | None = None
    description: str = ""
    sources: dict[str, str] = field(default_factory=dict, compare=False)
    warnings: tuple[str, ...] = ()
    path: Path | None = None
    cad_dir: Path | None = None

    @property
    def rotor_count(self) -> int:
        return len(self.rotors)

    @property
    def rotor_positions(self) -> np.ndarray:
        """(R, 3) hub positions, body frame (m)."""
        return np.array([r.position for r in self.rotors])

    @property
    def rotor_axes(self) -> np.ndarray:
        """(R, 3) unit thrust axes, body frame."""
        return np.array([r.axis for r in self.rotors])

    @property
    def rotor_spins(self) -> np.ndarray:
        """(R,) +1 for ccw, -1 for cw."""
        return np.array([r.spin for r in self.rotors])

    @property
    def weight(self) -> float:
        """m g (N)."""
        return self.mass * self.gravity

    def replace(self, **changes) -> VehicleParams:
        """A copy with some fields changed, validated again when the validated field (the
        inertia, :func:`check_physical`) is among them (the fits replace a parameter set
        thousands of times per flight)."""
        fields = _FIELDS.get(type(self))
        if fields is None:
            fields = _FIELDS[type(self)] = tuple(f.name for f in dataclasses.fields(self)
                                                 if f.init)
        if type(self).__dict__.get("__post_init__") is not None or \
                not changes.keys() <= set(fields):
            new = dataclasses.replace(self, **changes)
        else:
            # the object dataclasses.replace builds (every init field, the changed ones
            # new), without its per-field __init__ on the frozen class
            new = object.__new__(type(self))
            own = self.__dict__
            new.__dict__.update({name: own[name] for name in fields})
            new.__dict__.update(changes)
        if "inertia" in changes:
            check_physical(new, where=new.path or new.name)
        return new


#: the init fields' names per VehicleParams class (:meth:`VehicleParams.replace`)
_FIELDS: dict[type, tuple[str, ...]] = {}


# ----------------------------------------------------------------------------- validation


#: relative tolerance of the triangle inequality A + B >= C (1 - TRIANGLE_RTOL) of the
#: principal moments (dimensionless; the round-off of summing moments, far below any
#: physical difference): moments on the flat-body wall A + B = C pass
TRIANGLE_RTOL = 1e-9


def inertia_problems(inertia: np.ndarray) -> list[str]:
    """Reasons why ``inertia`` (3, 3) cannot be a rigid body's inertia tensor (empty if it can).

    A real tensor is symmetric, positive definite, and its principal moments obey the
    triangle inequality A + B >= C for every ordering (MuJoCo checks the same)."""
    inertia = np.asarray(inertia, dtype=float)
    problems = []
    if inertia.shape != (3, 3):
        return ["must be a finite 3x3 matrix"]
    # in Python floats (the same float64 values and comparisons; this runs thousands of
    # times per fit, where numpy's per-call cost on a 3x3 array was most of it)
    values = inertia.tolist()
    if not all(map(math.isfinite, values[0] + values[1] + values[2])):
        return ["must be a finite 3x3 matrix"]
    (a, b, c), (d, e, f), (g, h, i) = values
    if b == c == d == f == g == h == 0.0:
        # a diagonal tensor (the usual case): symmetric, its principal moments are its
        # diagonal -- the same test as below without eigvalsh
        low, mid, high = sorted((a, e, i))
        if low > 0 and low + mid >= high * (1 - TRIANGLE_RTOL):
            return []
    if not np.allclose(inertia, inertia.T, rtol=1e-9, atol=1e-15):
        problems.append("is not symmetric")
    moments = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    if np.any(moments <= 0):
        problems.append(f"principal moments {moments.tolist()} are not all positive")
    else:
        a, b, c = np.sort(moments)
        if a + b < c * (1 - TRIANGLE_RTOL):
            problems.append(
                f"principal moments break the triangle inequality: {a:.6g} + {b:.6g} < {c:.6g}"
                " (no rigid body has this inertia; MuJoCo refuses it)"
            )
    return problems


def check_physical(params: VehicleParams, *, where: object) -> None:
    """Raise :class:`ModelError` if ``params`` cannot describe a rigid vehicle."""
    problems = inertia_problems(params.inertia)
    if problems:
        raise ModelError(f"{where}: body.inertia: " + "; ".join(problems))


# ----------------------------------------------------------------------------- loading

_BODY_UNITS = {"mass": "kg", "com": "m", "inertia": "kg m^2"}
_ROTOR_UNITS = {
    "thrust_factor": "N s^2/rad^2",
    "drag_factor": "N m s^2/rad^2",
    "max_speed": "rad/s",
    "min_speed": "rad/s",
    "radius": "m",
    "inertia": "kg m^2",
}
_ENV_UNITS = {"gravity": "m/s^2", "air_density": "kg/m^3"}
_TOP_KEYS = {"schema", "name", "description", "body", "rotors", "rotor", "rotor_layout",
             "environment", "motor_map", "warnings", "notes"}


def builtin_names() -> list[str]:
    """Names of the parameter sets shipped in ``models/``."""
    return sorted(p.stem for p in MODELS_DIR.glob("*.toml"))


def resolve_params_path(name_or_path: str | Path) -> Path:
    """``physical`` -> models/physical.toml; a path is taken as it is."""
    text = str(name_or_path)
    candidate = Path(text)
    if candidate.suffix == ".toml" or candidate.exists():
        if not candidate.is_file():
            raise InputError(f"{candidate}: parameter file not found")
        return candidate
    builtin = MODELS_DIR / f"{text}.toml"
    if builtin.is_file():
        return builtin
    raise InputError(
        f"unknown model {text!r}: valid names are {', '.join(builtin_names())} "
        "or a path to a parameter TOML file"
    )


def read_quantity(table: dict, key: str, unit: str, path: Path, section: str, *, shape=()):
    where = f"{section}.{key}"
    entry = table.get(key)
    if not isinstance(entry, dict):
        raise field_error(path, where, "expected an inline table { value, unit, source }")
    extra = set(entry) - {"value", "unit", "source", "note"}
    if extra:
        raise field_error(path, where,
                          f"unknown keys {sorted(extra)}; valid: value, unit, source, note")
    for needed in ("value", "unit", "source"):
        if needed not in entry:
            raise field_error(path, where,
                              f"missing '{needed}' (every number states its unit and source)")
    if entry["unit"] != unit:
        raise field_error(path, where, f"unit {entry['unit']!r} where {unit!r} is expected")
    try:
        value = np.asarray(entry["value"], dtype=float)
    except (TypeError, ValueError):
        raise field_error(path, where, f"value {entry['value']!r} is not numeric") from None
    if value.shape != shape:
        raise field_error(path, where, f"expected shape {shape}, got {value.shape}")
    if not np.all(np.isfinite(value)):
        raise field_error(path, where, "value is NaN or infinite")
    return (float(value) if shape == () else value), str(entry["source"])


def _positive(value: float, path: Path, where: str, *, allow_zero=False) -> float:
    if value < 0 or (value == 0 and not allow_zero):
        raise field_error(path, where, f"must be {'>= 0' if allow_zero else '> 0'}, got {value}")
    return value


def _check_keys(table: dict, valid: set[str], path: Path, section: str) -> None:
    unknown = set(table) - valid
    if unknown:
        raise field_error(path, section or "top level",
                          f"unknown key(s) {sorted(unknown)}; "
                          f"valid keys: {', '.join(sorted(valid))}")


def cad_path(spec: dict, path: Path, where: str) -> tuple[Path, str]:
    if not isinstance(spec, dict) or "path" not in spec or "source" not in spec:
        raise field_error(path, where, "expected { path = \"<cad folder>\", source = \"...\" }")
    return (path.parent / spec["path"]).resolve(), str(spec["source"])


def rotor_table(entries: list, path: Path) -> tuple[Rotor, ...]:
    rotors = []
    for i, entry in enumerate(entries):
        section = f"rotor[{i}]"
        _check_keys(entry, {"name", "position", "axis", "spin"}, path, section)
        position, _ = read_quantity(entry, "position", "m", path, section, shape=(3,))
        axis = np.asarray(entry.get("axis", [0.0, 0.0, 1.0]), dtype=float)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-9:
            raise field_error(path, f"{section}.axis", "must be a non-zero 3-vector")
        spin = entry.get("spin")
        if spin not in SPIN_SIGN:
            raise field_error(path, f"{section}.spin", f"must be 'ccw' or 'cw', got {spin!r}")
        rotors.append(Rotor(str(entry.get("name", i + 1)), position,
                            axis / np.linalg.norm(axis), SPIN_SIGN[spin]))
    return tuple(rotors)


def load_params(name_or_path: str | Path, *, check: bool = True) -> VehicleParams:
    """Load a parameter set by built-in name or path; validate units, shapes and physics.

    ``check=False`` skips the physical-inertia check (the analytic engine can still run a
    set such as ``report`` whose published inertia no rigid body has; MuJoCo cannot)."""
    path = resolve_params_path(name_or_path)
    data = read_toml(path)
    _check_keys(data, _TOP_KEYS, path, "")
    data = check_schema(data, path, SCHEMA, EARLIER_SCHEMAS)
    sources: dict[str, str] = {}
    cad_dir = None

    body = data.get("body")
    if not isinstance(body, dict):
        raise field_error(path, "body", "missing section [body]")
    _check_keys(body, set(_BODY_UNITS) | {"from_cad"}, path, "body")
    if "from_cad" in body:
        from ..cad.assembly import load_assembly  # local: only sets that use CAD need trimesh
        from ..cad.massprops import vehicle_mass_properties

        cad_dir, source = cad_path(body["from_cad"], path, "body.from_cad")
        props = vehicle_mass_properties(load_assembly(cad_dir))
        mass, com, inertia = props.mass, props.com, props.inertia
        sources.update(mass=source, com=source, inertia=source)
    else:
        mass, sources["mass"] = read_quantity(body, "mass", "kg", path, "body")
        com, sources["com"] = read_quantity(body, "com", "m", path, "body", shape=(3,))
        inertia, sources["inertia"] = read_quantity(body, "inertia", "kg m^2", path, "body",
                                                shape=(3, 3))
    _positive(mass, path, "body.mass")

    rotor_section = data.get("rotors")
    if not isinstance(rotor_section, dict):
        raise field_error(path, "rotors", "missing section [rotors] (b, d, speed range)")
    _check_keys(rotor_section, set(_ROTOR_UNITS), path, "rotors")
    values = {}
    for key, unit in _ROTOR_UNITS.items():
        if key in ("min_speed", "radius", "inertia") and key not in rotor_section:
            values[key] = 0.0
            continue
        values[key], sources[f"rotors.{key}"] = read_quantity(rotor_section, key, unit, path,
                                                              "rotors")
        _positive(values[key], path, f"rotors.{key}", allow_zero=key in ("min_speed", "inertia"))
    if values["min_speed"] >= values["max_speed"]:
        raise field_error(path, "rotors.min_speed", "must be below rotors.max_speed")

    if "rotor_layout" in data:
        from ..cad.assembly import load_assembly

        layout_dir, source = cad_path(data["rotor_layout"].get("from_cad"), path,
                                       "rotor_layout.from_cad")
        cad_dir = cad_dir or layout_dir
        rotors = tuple(
            Rotor(r.name, np.asarray(r.position, float), np.asarray(r.axis, float), float(r.spin))
            for r in load_assembly(layout_dir).rotors
        )
        sources["rotor_layout"] = source
    elif "rotor" in data:
        rotors = rotor_table(data["rotor"], path)
    else:
        raise field_error(path, "rotor", "no rotors: give [[rotor]] entries or [rotor_layout]")
    if not rotors:
        raise field_error(path, "rotor", "no rotors")

    env = data.get("environment", {})
    _check_keys(env, set(_ENV_UNITS), path, "environment")
    gravity, air_density = 9.81, 1.225
    if "gravity" in env:
        gravity, sources["gravity"] = read_quantity(env, "gravity", "m/s^2", path, "environment")
    if "air_density" in env:
        air_density, sources["air_density"] = read_quantity(env, "air_density", "kg/m^3", path,
                                                       "environment")

    motor_map = None
    if "motor_map" in data:
        mm = data["motor_map"]
        _check_keys(mm, {"command_unit", "command", "speed", "reference_voltage",
                         "voltage_gain", "time_constant"}, path, "motor_map")
        unit = mm.get("command_unit")
        if not isinstance(unit, str):
            raise field_error(path, "motor_map.command_unit", "missing (name the command's unit)")
        command, source = read_quantity(mm, "command", unit, path, "motor_map",
                                    shape=(len(mm.get("command", {}).get("value", [])),))
        speed, _ = read_quantity(mm, "speed", "rad/s", path, "motor_map",
                             shape=(len(rotors), command.shape[0]))
        if np.any(np.diff(command) <= 0):
            raise field_error(path, "motor_map.command", "must be strictly increasing")
        extra = {}
        for key, unit_x in (("reference_voltage", "V"), ("voltage_gain", "1/V"),
                            ("time_constant", "s")):
            if key in mm:
                extra[key], sources[f"motor_map.{key}"] = read_quantity(mm, key, unit_x, path,
                                                                    "motor_map")
        if extra.get("time_constant", 0.0) < 0:
            raise field_error(path, "motor_map.time_constant", "must be >= 0")
        if "voltage_gain" in extra and "reference_voltage" not in extra:
            raise field_error(path, "motor_map.reference_voltage",
                              "missing (voltage_gain needs the voltage the map was taken at)")
        motor_map = MotorMap(unit, command, speed, source, **extra)

    params = VehicleParams(
        name=str(data.get("name", path.stem)),
        mass=mass,
        com=np.asarray(com, dtype=float),
        inertia=np.asarray(inertia, dtype=float),
        rotors=rotors,
        thrust_factor=values["thrust_factor"],
        drag_factor=values["drag_factor"],
        max_speed=values["max_speed"],
        min_speed=values["min_speed"],
        rotor_radius=values["radius"],
        rotor_inertia=values["inertia"],
        gravity=gravity,
        air_density=air_density,
        motor_map=motor_map,
        description=str(data.get("description", "")),
        sources=sources,
        warnings=tuple(str(w) for w in data.get("warnings", [])),
        path=path,
        cad_dir=cad_dir,
    )
    from .guards import check_hover_control, check_vehicle  # local: guards reads VehicleParams

    if check:
        check_physical(params, where=path)
        check_vehicle(params, where=path)
    else:
        check_hover_control(params, where=path)
    return params


def hover_speed(params: VehicleParams) -> float:
    """Rotor speed (rad/s) at which equal rotors hold the vehicle's weight.

    Uses the vertical component of each rotor axis, so tilted rotors are handled."""
    lift_per_omega2 = params.thrust_factor * float(np.sum(params.rotor_axes[:, 2]))
    if lift_per_omega2 <= 0:
        raise ModelError(f"{params.path or params.name}: rotors give no upward thrust")
    return math.sqrt(params.weight / lift_per_omega2)
