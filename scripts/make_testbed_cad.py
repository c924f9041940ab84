"""Generate the testbed's CAD parts (binary STL, millimetres) and its assembly manifest.

Writes ``cad/*.stl`` and ``cad/testbed.toml`` from the report's measured dimensions and
masses (Table 4.4, Table 4.1, the motor designation Turnigy D2830-11) and from stated
assumptions where the report gives no dimension. Every part is one closed, consistently
wound shell (a prism of a convex polygon, or a hollow prism), so its volume, centre of mass
and inertia are exact for the polyhedron. The output is byte-identical on every run: fixed
STL header, float32 vertices, no timestamps.

Usage::

    python scripts/make_testbed_cad.py            # writes cad/
    python scripts/make_testbed_cad.py -o /tmp/cad

Mesh frames (mm): each part is drawn in its own frame (e.g. the motor's origin is the
centre of its mounting face); the manifest places it in the body frame (x forward, y left,
z up, origin at the frame's geometric centre on the arms' centre plane).
"""

from __future__ import annotations

import argparse
import math
import struct
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from quadsim.core.errors import run_cli  # noqa: E402
from quadsim.core.files import atomic_write_bytes, atomic_write_text  # noqa: E402
from quadsim.identify.benchdata import load_physical_measurements  # noqa: E402

STL_HEADER = b"quadsim testbed part, binary STL, units: millimetre".ljust(80, b" ")
CIRCLE_SEGMENTS = 64

# ----------------------------------------------------------------------------- mesh primitives


def regular_polygon(radius: float, segments: int) -> np.ndarray:
    """(segments, 2) counter-clockwise vertices on a circle of ``radius``."""
    angle = 2.0 * np.pi * np.arange(segments) / segments
    return radius * np.column_stack([np.cos(angle), np.sin(angle)])


def rectangle(width: float, depth: float) -> np.ndarray:
    """(4, 2) counter-clockwise corners of a ``width`` (x) by ``depth`` (y) rectangle."""
    x, y = 0.5 * width, 0.5 * depth
    return np.array([[-x, -y], [x, -y], [x, y], [-x, y]])


def prism(outline: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed prism of a convex, counter-clockwise ``outline`` (K, 2) from z=0 to z=height.

    Returns vertices (2K, 3) and outward-wound triangles (4K-4, 3)."""
    k = len(outline)
    vertices = np.vstack([np.column_stack([outline, np.zeros(k)]),
                          np.column_stack([outline, np.full(k, height)])])
    fan = np.array([[0, i, i + 1] for i in range(1, k - 1)])
    bottom, top = fan[:, ::-1], fan + k
    i = np.arange(k)
    j = (i + 1) % k
    sides = np.vstack([np.column_stack([i, j, j + k]), np.column_stack([i, j + k, i + k])])
    return vertices, np.vstack([bottom, top, sides])


def hollow_prism(outer: np.ndarray, inner: np.ndarray, height: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Closed hollow prism between two counter-clockwise outlines with the same vertex count
    (the inner one strictly inside the outer), from z=0 to z=height."""
    k = len(outer)
    rings = [np.column_stack([outline, np.full(k, z)])
             for z in (0.0, height) for outline in (outer, inner)]
    vertices = np.vstack(rings)  # 0: outer bottom, k: inner bottom, 2k: outer top, 3k: inner top
    i = np.arange(k)
    j = (i + 1) % k

    def quads(a, b, c, d):  # quad a-b-c-d, counter-clockwise seen from outside
        return np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])

    ob, ib, ot, it = 0, k, 2 * k, 3 * k
    faces = np.vstack([
        quads(ob + i, ob + j, ot + j, ot + i),  # outer wall, normals outward
        quads(ib + j, ib + i, it + i, it + j),  # inner wall, normals toward the hole
        quads(ot + i, ot + j, it + j, it + i),  # top annulus, normals +z
        quads(ob + j, ob + i, ib + i, ib + j),  # bottom annulus, normals -z
    ])
    return vertices, faces


def box(size_x: float, size_y: float, size_z: float):
    """Box centred on the origin."""
    vertices, faces = prism(rectangle(size_x, size_y), size_z)
    return vertices - [0.0, 0.0, 0.5 * size_z], faces


def along_x(vertices: np.ndarray) -> np.ndarray:
    """Turn a prism extruded along z into one extruded along x (right-handed: z->x, x->y,
    y->z), so a bar's length runs along x."""
    return vertices[:, [2, 0, 1]]


def square_hollow_bar(length: float, outer: float, wall: float):
    """Square hollow bar along x from x=0 to x=length, centred on the x axis."""
    vertices, faces = hollow_prism(rectangle(outer, outer),
                                   rectangle(outer - 2 * wall, outer - 2 * wall), length)
    return along_x(vertices), faces


def cylinder(diameter: float, height: float, segments: int = CIRCLE_SEGMENTS):
    """Cylinder (a regular prism) on the xy plane from z=0 to z=height."""
    return prism(regular_polygon(0.5 * diameter, segments), height)


def stl_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """Binary STL with the fixed header; float32 normals and vertices."""
    triangles = vertices[faces]
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    record = np.zeros(len(faces), dtype=[("normal", "<f4", 3), ("vertices", "<f4", (3, 3)),
                                          ("attribute", "<u2")])
    record["normal"] = normals
    record["vertices"] = triangles
    return STL_HEADER + struct.pack("<I", len(faces)) + record.tobytes()


# ----------------------------------------------------------------------------- the testbed
# Measured: report Table 4.4, mean of the three trials, from the package's transcription
# (quadsim/identify/data/table_4_4_physical.csv) so that the numbers live in one place. SI.
TABLE_4_4 = {k: float(np.mean(v)) for k, v in load_physical_measurements().columns.items()
             if k != "trial"}
TOTAL_MASS = TABLE_4_4["total_mass"]            # overall mass, weighed
MECHANICAL_MASS = TABLE_4_4["mechanical_mass"]  # mechanical parts (Table 4.1 list), weighed
BATTERY_MASS = TABLE_4_4["battery_mass"]
MOTOR_MASS = TABLE_4_4["motor_mass"]
PROPELLER_MASS = TABLE_4_4["propeller_mass"]
FRAME_GROUP_MASS = TABLE_4_4["base_mass"]       # "upper and lower base with frames attached" M
FRAME_LENGTH_MM = 1000 * TABLE_4_4["frame_length"]       # l_f
ARM_MM = 1000 * TABLE_4_4["motor_to_centre"]             # l_mtc, motor axis to centre
BASE_RADIUS_MM = 1000 * TABLE_4_4["base_radius"]         # R_b (half the side of the base)

# Assumed dimensions (mm) -- the report gives none; each has its reason in the manifest.
ARM_OUTER_MM, ARM_WALL_MM = 12.7, 1.2
PLATE_THICKNESS_MM = 2.0
GEAR_OUTER_MM, GEAR_WALL_MM, GEAR_LENGTH_MM, GEAR_RADIUS_MM = 10.0, 1.0, 100.0, 100.0
MOTOR_DIAMETER_MM, MOTOR_LENGTH_MM = 28.0, 30.0
SCREW_DIAMETER_MM, SCREW_LENGTH_MM = 8.0, 4.0
PROP_LENGTH_MM, PROP_CHORD_MM, PROP_THICKNESS_MM = 254.0, 18.0, 2.0
CAP_DIAMETER_MM, CAP_LENGTH_MM = 10.0, 8.0
BATTERY_MM = (105.0, 34.0, 24.0)
ARDUINO_MM, ARDUINO_MASS = (68.6, 53.4, 10.0), 0.025
IMU_MM, IMU_MASS = (25.8, 16.8, 3.0), 0.003
ESC_MM = (40.0, 20.0, 8.0)

# Heights (mm) in the body frame: arms centred on z=0, plates above and below them.
ARM_TOP = 0.5 * ARM_OUTER_MM
PLATE_Z = ARM_TOP + 0.5 * PLATE_THICKNESS_MM
MOTOR_TOP = ARM_TOP + MOTOR_LENGTH_MM
HUB_Z = MOTOR_TOP + SCREW_LENGTH_MM + 0.5 * PROP_THICKNESS_MM

# Report numbering, eq. 3.44-3.47: yaw of each arm (deg) and spin of its rotor.
ROTORS = (("1", 0.0, "ccw"), ("2", -90.0, "cw"), ("3", 180.0, "ccw"), ("4", 90.0, "cw"))


def volume_mm3(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume of a closed outward-wound mesh (divergence theorem)."""
    t = vertices[faces]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def _on_arm(radius_mm: float, z_mm: float, extra_yaw: float = 0.0) -> list[dict]:
    """One placement per arm at ``radius_mm`` from the centre along the arm, height z."""
    out = []
    for name, yaw, _ in ROTORS:
        c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        out.append({"name": name, "position_m": [radius_mm * c / 1000, radius_mm * s / 1000,
                                                  z_mm / 1000],
                    "rpy_deg": [0.0, 0.0, yaw + extra_yaw]})
    return out


def testbed_parts() -> list[dict]:
    """Parts with mesh, placements, group, and mass (kg) or None where split later."""
    arm_inner = ARM_MM + 0.5 * ARM_OUTER_MM - FRAME_LENGTH_MM
    diagonal = [{"name": f"{q}", "position_m": [0.045 * math.cos(math.radians(a)),
                                                0.045 * math.sin(math.radians(a)), 0.0],
                 "rpy_deg": [0.0, 0.0, a]} for q, a in zip("abcd", (45, 135, 225, 315))]
    parts = [
        dict(name="base_plate", shape=box(2 * BASE_RADIUS_MM, 2 * BASE_RADIUS_MM,
                                          PLATE_THICKNESS_MM), group="mechanical",
             collision="box",
             placements=[{"name": "upper", "position_m": [0, 0, PLATE_Z / 1000]},
                         {"name": "lower", "position_m": [0, 0, -PLATE_Z / 1000]}],
             geometry=f"square of side 2 R_b = {2 * BASE_RADIUS_MM:.3f} mm (Table 4.4); "
                      f"assumed: {PLATE_THICKNESS_MM} mm thick aluminium sheet, chosen so that "
                      "the frame group's implied density is that of aluminium"),
        dict(name="frame_arm", shape=square_hollow_bar(FRAME_LENGTH_MM, ARM_OUTER_MM,
                                                       ARM_WALL_MM), group="mechanical",
             collision="box", placements=_on_arm(arm_inner, 0.0),
             geometry=f"square hollow bar, length l_f = {FRAME_LENGTH_MM} mm (Table 4.4); "
                      f"assumed: 1/2 inch ({ARM_OUTER_MM} mm) section, {ARM_WALL_MM} mm wall "
                      "(common aluminium stock); outer end 6.35 mm past the motor axis"),
        dict(name="landing_gear", shape=square_hollow_bar(GEAR_LENGTH_MM, GEAR_OUTER_MM,
                                                          GEAR_WALL_MM), group="mechanical",
             collision="box",
             placements=[{**p, "rpy_deg": [0.0, 90.0, p["rpy_deg"][2]]}
                         for p in _on_arm(GEAR_RADIUS_MM, -ARM_TOP)],
             geometry="hollow bar like the frame (report 3.2.3); assumed: 10 mm square, 1 mm "
                      "wall, 100 mm vertical leg under each arm at 100 mm from the centre"),
        dict(name="motor", shape=cylinder(MOTOR_DIAMETER_MM, MOTOR_LENGTH_MM),
             group="mechanical", mass=MOTOR_MASS, collision="cylinder",
             placements=_on_arm(ARM_MM, ARM_TOP),
             geometry="Turnigy D2830-11: 28 mm diameter, 30 mm long (the designation); solid "
                      "cylinder, shaft omitted; sits on the arm above the hub"),
        dict(name="propeller_screw", shape=cylinder(SCREW_DIAMETER_MM, SCREW_LENGTH_MM),
             group="mechanical", collision="none", placements=_on_arm(ARM_MM, MOTOR_TOP),
             geometry="assumed: prop adapter collar 8 mm diameter, 4 mm, between motor and "
                      "propeller"),
        dict(name="propeller", shape=box(PROP_LENGTH_MM, PROP_CHORD_MM, PROP_THICKNESS_MM),
             group="mechanical", mass=PROPELLER_MASS, collision="none",
             placements=_on_arm(ARM_MM, HUB_Z, extra_yaw=45.0),
             geometry="10 inch (254 mm) two-blade propeller as a flat blade; assumed: 18 mm "
                      "chord, 2 mm thick; blade frozen at 45 deg to its arm, where a spinning "
                      "blade's time-averaged inertia is (Ixx = Iyy); mesh origin = hub"),
        dict(name="propeller_head_cap", shape=cylinder(CAP_DIAMETER_MM, CAP_LENGTH_MM),
             group="mechanical", collision="none",
             placements=_on_arm(ARM_MM, HUB_Z + 0.5 * PROP_THICKNESS_MM),
             geometry="assumed: prop nut 10 mm diameter, 8 mm tall, above the propeller"),
        dict(name="battery", shape=box(*BATTERY_MM), group="battery", mass=BATTERY_MASS,
             collision="box",
             placements=[{"name": "1", "position_m": [0, 0, -(PLATE_Z + 0.5 * PLATE_THICKNESS_MM
                                                              + 0.5 * BATTERY_MM[2]) / 1000]}],
             geometry="assumed: 3S 2200 mAh LiPo pack 105 x 34 x 24 mm (typical for 171 g), "
                      "strapped under the lower base, long side along x"),
        dict(name="arduino_uno", shape=box(*ARDUINO_MM), group="avionics", mass=ARDUINO_MASS,
             collision="none",
             placements=[{"name": "1", "position_m": [0, 0, (PLATE_Z + 0.5 * PLATE_THICKNESS_MM
                                                             + 0.5 * ARDUINO_MM[2]) / 1000]}],
             geometry="Arduino Uno board 68.6 x 53.4 mm, 25 g (Arduino datasheet); assumed "
                      "10 mm component envelope, on the upper base"),
        dict(name="imu", shape=box(*IMU_MM), group="avionics", mass=IMU_MASS, collision="none",
             placements=[{"name": "1", "position_m": [0, 0, (PLATE_Z + 0.5 * PLATE_THICKNESS_MM
                                                             + ARDUINO_MM[2]
                                                             + 0.5 * IMU_MM[2]) / 1000]}],
             geometry="ADXL345 + L3G4200D 10-DOF breakout (report 3.2.5); assumed 25.8 x 16.8 "
                      "x 3 mm, 3 g, on top of the Arduino at the centre"),
        dict(name="esc", shape=box(*ESC_MM), group="avionics", collision="none",
             placements=diagonal,
             geometry="assumed: 40 x 20 x 8 mm ESC between the bases in the four diagonals "
                      "(report 3.2.3: the space between the bases holds ESCs and power cables)"),
    ]
    return parts


def assign_masses(parts: list[dict]) -> None:
    """Give every part its mass per instance (kg) and the mass's source.

    Measured masses are used as they are. Groups weighed together are split in proportion to
    modelled volume (one material per group): the frame group M over bases, arms and landing
    gear; the mechanical residual over propeller screws and caps; the avionics residual over
    the ESCs (with their wiring)."""
    by_name = {p["name"]: p for p in parts}
    for p in parts:
        p["volume_mm3"] = volume_mm3(*p["shape"])
        p["count"] = len(p["placements"])
    sources = {
        "motor": "Table 4.4 m_m (weighed, mean of 3 trials)",
        "propeller": "Table 4.4 m_p (weighed, mean of 3 trials)",
        "battery": "Table 4.4 m_b (weighed, mean of 3 trials)",
        "arduino_uno": "Arduino Uno datasheet (25 g)",
        "imu": "assumed: typical 10-DOF breakout board",
    }
    for name, source in sources.items():
        by_name[name]["source"] = source

    def split(names: list[str], total: float, source: str) -> None:
        volume = sum(by_name[n]["volume_mm3"] * by_name[n]["count"] for n in names)
        for n in names:
            by_name[n]["mass"] = total * by_name[n]["volume_mm3"] / volume
            by_name[n]["source"] = (f"{source}, split by modelled volume (implied density "
                                    f"{total / (volume * 1e-9):.0f} kg/m^3)")

    split(["base_plate", "frame_arm", "landing_gear"], FRAME_GROUP_MASS,
          f"Table 4.4 M = {FRAME_GROUP_MASS:.6f} kg (bases with frames attached; landing gear "
          "assumed attached when weighed)")
    residual = MECHANICAL_MASS - FRAME_GROUP_MASS - 4 * (MOTOR_MASS + PROPELLER_MASS)
    split(["propeller_screw", "propeller_head_cap"], residual,
          f"Table 4.4 m_mp - M - 4 (m_m + m_p) = {1000 * residual:.3f} g residual of the "
          "mechanical parts")
    esc_total = TOTAL_MASS - MECHANICAL_MASS - BATTERY_MASS - ARDUINO_MASS - IMU_MASS
    split(["esc"], esc_total,
          "Table 4.4 m_total - m_mp - m_b - Arduino - IMU (ESCs with power wiring)")


def _toml_list(values) -> str:
    return "[" + ", ".join(repr(round(float(v), 9) + 0.0) for v in values) + "]"


def manifest_text(parts: list[dict]) -> str:
    """The assembly manifest (schema quadsim.cad/1) for ``parts``."""
    lines = [
        "# Testbed assembly manifest, written by scripts/make_testbed_cad.py (do not edit by",
        "# hand: change the generator). Schema: docs/cad.md. Report: Table 4.1 (parts), 4.4.",
        'schema = "quadsim.cad/1"',
        'name = "testbed"',
        'description = "0.84 kg \'+\' quadrotor testbed of the 2015 report, rebuilt from its '
        'measured dimensions and masses"',
        'mesh_unit = "mm"',
        "",
        "[vehicle]",
        f'weighed_mass = {{ value = {TOTAL_MASS!r}, unit = "kg", source = "Table 4.4 overall '
        'mass, mean of 3 trials" }',
        "mass_tolerance = 0.005",
    ]
    for p in parts:
        lines += ["", "[[part]]", f'name = "{p["name"]}"', f'mesh = "{p["name"]}.stl"',
                  f'group = "{p["group"]}"',
                  f'mass = {{ value = {round(p["mass"], 12)!r}, unit = "kg", '
                  f'source = "{p["source"]}" }}',
                  f'collision = "{p["collision"]}"', f'geometry = "{p["geometry"]}"']
        for pl in p["placements"]:
            fields = [f'name = "{pl["name"]}"', f'position_m = {_toml_list(pl["position_m"])}']
            if "rpy_deg" in pl and any(pl["rpy_deg"]):
                fields.append(f'rpy_deg = {_toml_list(pl["rpy_deg"])}')
            lines.append("[[part.placement]]")
            lines += fields
    lines += ["", "# Rotors in the report's numbering (eq. 3.44-3.47): 1 front (+x) ccw, "
              "2 right (-y) cw,", "# 3 back (-x) ccw, 4 left (+y) cw. Hub = the propeller "
              "placement's origin, axis = its z axis."]
    for name, _, spin in ROTORS:
        lines += ["[[rotor]]", f'name = "{name}"', 'part = "propeller"',
                  f'placement = "{name}"', f'spin = "{spin}"']
    return "\n".join(lines) + "\n"


def write_testbed(out_dir: Path) -> list[Path]:
    """Write every STL and the manifest into ``out_dir``; return the paths written."""
    parts = testbed_parts()
    assign_masses(parts)
    written = [atomic_write_bytes(out_dir / f"{p['name']}.stl", stl_bytes(*p["shape"]),
                                  make_parents=True)
               for p in parts]
    written.append(atomic_write_text(out_dir / "testbed.toml", manifest_text(parts),
                                     make_parents=True))
    return written


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Write the testbed's parts as binary STL (mm) and the assembly manifest "
                    "cad/testbed.toml, from the report's dimensions and masses.")
    parser.add_argument("-o", "--out", type=Path, default=REPO / "cad",
                        help="output folder (default: cad/ in the repository)")
    args = parser.parse_args(argv)
    for path in write_testbed(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
