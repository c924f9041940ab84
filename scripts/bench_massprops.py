"""Benchmark: mass properties and MJCF build for an assembly of 1,000,000 triangles.

Target: <= 5 s on 2 cores for loading + validating the meshes, their mass
properties, and building + writing the MJCF (including MuJoCo's compile check). The
assembly is synthetic: twelve icospheres (6 subdivisions, 81,920 triangles each) and a
16,960-triangle motor cylinder on four arms -- exactly 1,000,000 unique mesh triangles in
binary STL (mm); each file under MuJoCo's 200,000-faces-per-STL limit. Run on 2 cores as::

    taskset -c 0,1 python scripts/bench_massprops.py            # prints the timings

Results go in docs/cad.md (never in a timed test).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import statistics
import sys
import tempfile
import time
from pathlib import Path

import trimesh

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from quadsim.cad.assembly import load_assembly  # noqa: E402
from quadsim.cad.massprops import vehicle_mass_properties  # noqa: E402
from quadsim.sim.model import build_model, write_model  # noqa: E402


def _generator():
    spec = importlib.util.spec_from_file_location("make_testbed_cad",
                                                  REPO / "scripts" / "make_testbed_cad.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_big_assembly(folder: Path) -> int:
    """Write the 1,000,000-triangle CAD folder; return its triangle count.

    Twelve icosphere parts (6 subdivisions, 81,920 triangles each) around a centre and a
    16,960-triangle motor cylinder on four arms. Each mesh stays under MuJoCo's limit of
    200,000 faces per STL file."""
    gen = _generator()
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=20.0)
    sphere_stl = gen.stl_bytes(sphere.vertices, sphere.faces)
    motor = gen.cylinder(28.0, 30.0, segments=4241)
    (folder / "motor.stl").write_bytes(gen.stl_bytes(*motor))
    lines = ['schema = "quadsim.cad/1"', 'name = "bench"', 'mesh_unit = "mm"']
    for k in range(12):
        angle = 2 * math.pi * k / 12
        (folder / f"part{k}.stl").write_bytes(sphere_stl)
        lines += ["[[part]]", f'name = "part{k}"', f'mesh = "part{k}.stl"',
                  'mass = { value = 0.03, unit = "kg", source = "bench" }',
                  "[[part.placement]]", 'name = "1"',
                  f"position_m = [{0.08 * math.cos(angle)!r}, {0.08 * math.sin(angle)!r}, 0.0]"]
    lines += ["[[part]]", 'name = "motor"', 'mesh = "motor.stl"',
              'mass = { value = 0.052, unit = "kg", source = "bench" }']
    for i, (x, y) in enumerate(((0.2, 0.0), (0.0, -0.2), (-0.2, 0.0), (0.0, 0.2))):
        lines += ["[[part.placement]]", f'name = "{i + 1}"', f"position_m = [{x}, {y}, 0.0]"]
    for i, spin in enumerate(("ccw", "cw", "ccw", "cw")):
        lines += ["[[rotor]]", f'name = "{i + 1}"', 'part = "motor"', f'placement = "{i + 1}"',
                  f'spin = "{spin}"']
    (folder / "bench.toml").write_text("\n".join(lines) + "\n")
    return 12 * len(sphere.faces) + len(motor[1])


def run_once(folder: Path) -> dict[str, tuple[float, float]]:
    """(wall s, CPU s of this process) per stage for one full build."""
    times = {}

    def stage(name, func):
        wall, cpu = time.perf_counter(), time.process_time()
        result = func()
        times[name] = (time.perf_counter() - wall, time.process_time() - cpu)
        return result

    assembly = stage("load + validate meshes + mesh integrals", lambda: load_assembly(folder))
    stage("combine (placements, parallel axis)", lambda: vehicle_mass_properties(assembly))
    model = stage("build_model (all of the above + XML)",
                  lambda: build_model(folder, output=folder / "bench.xml"))
    stage("MuJoCo compile check + atomic write",
          lambda: write_model(model, folder / "bench.xml"))
    build, write = times["build_model (all of the above + XML)"], \
        times["MuJoCo compile check + atomic write"]
    times["CLI path total"] = (build[0] + write[0], build[1] + write[1])
    return times


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs (median reported)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        triangles = write_big_assembly(folder)
        runs = [run_once(folder) for _ in range(args.repeat)]
    print(f"assembly: {triangles:,} triangles in 13 meshes, 16 placed instances, 4 rotors")
    print(f"{'stage':<42} {'wall s (median, min)':>22} {'CPU s (median)':>15}")
    for stage in runs[0]:
        wall = [r[stage][0] for r in runs]
        cpu = [r[stage][1] for r in runs]
        print(f"{stage:<42} {statistics.median(wall):12.2f} {min(wall):8.2f} "
              f"{statistics.median(cpu):15.2f}")
    total = statistics.median(r["CLI path total"][0] for r in runs)
    print(f"target <= 5 s: {'met' if total <= 5 else 'NOT met'} ({total:.2f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
