"""Write the small STEP (ISO 10303-21, AP214) test fixtures in tests/data/ by hand, no CAD kernel.

    python scripts/make_step_fixture.py

Writes, in millimetres (``SI_UNIT(.MILLI.,.METRE.)``):

* ``box.step``: 40 x 30 x 20 mm box, one corner at the origin (one closed B-rep solid);
* ``box.stl``: the same box as a binary STL (12 triangles, mm) - the exact reference;
* ``cylinder.step``: r = 10 mm, h = 30 mm cylinder on the z axis (a curved part: its mass
  properties depend on the tessellation tolerance and converge to the closed form);
* ``open_box.step``: the box without its top face (an open shell);
* ``two_boxes.step``: two disjoint boxes (two solids in one file).

The files are deterministic (fixed timestamp) and committed; run again only to change them.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "tests" / "data"
BOX = (40.0, 30.0, 20.0)              # mm
CYLINDER = (10.0, 30.0)               # radius, height (mm)


class Step:
    """Accumulates numbered entity instances."""

    def __init__(self):
        self.lines: list[str] = []

    def add(self, text: str) -> str:
        self.lines.append(text)
        return f"#{len(self.lines)}"

    def point(self, p) -> str:
        return self.add("CARTESIAN_POINT('',(" + ",".join(f"{float(x):.6f}" for x in p) + "))")

    def direction(self, d) -> str:
        return self.add("DIRECTION('',(" + ",".join(f"{float(x):.6f}" for x in d) + "))")

    def axis(self, origin, z, x) -> str:
        return self.add(f"AXIS2_PLACEMENT_3D('',{self.point(origin)},{self.direction(z)},"
                        f"{self.direction(x)})")

    def vertex(self, p) -> str:
        return self.add(f"VERTEX_POINT('',{self.point(p)})")

    def line_edge(self, v1, v2, p1, p2) -> str:
        d = np.subtract(p2, p1)
        length = float(np.linalg.norm(d))
        vec = self.add(f"VECTOR('',{self.direction(d / length)},{length:.6f})")
        line = self.add(f"LINE('',{self.point(p1)},{vec})")
        return self.add(f"EDGE_CURVE('',{v1},{v2},{line},.T.)")

    def face(self, surface: str, oriented: list[tuple[str, bool]]) -> str:
        edges = ",".join(self.add(f"ORIENTED_EDGE('',*,*,{e},{'.T.' if s else '.F.'})")
                         for e, s in oriented)
        loop = self.add(f"EDGE_LOOP('',({edges}))")
        bound = self.add(f"FACE_OUTER_BOUND('',{loop},.T.)")
        return self.add(f"ADVANCED_FACE('',({bound}),{surface},.T.)")

    def text(self, name: str, items: list[str]) -> str:
        units = [self.add("(LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.))")]
        units.append(self.add("(NAMED_UNIT(*) PLANE_ANGLE_UNIT() SI_UNIT($,.RADIAN.))"))
        units.append(self.add("(NAMED_UNIT(*) SI_UNIT($,.STERADIAN.) SOLID_ANGLE_UNIT())"))
        unc = self.add(f"UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE(1.E-07),{units[0]},"
                       "'distance_accuracy_value','confusion accuracy')")
        ctx = self.add(f"(GEOMETRIC_REPRESENTATION_CONTEXT(3) GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT"
                       f"(({unc})) GLOBAL_UNIT_ASSIGNED_CONTEXT(({','.join(units)})) "
                       "REPRESENTATION_CONTEXT('Context #1','3D Context with UNIT and "
                       "UNCERTAINTY'))")
        app = self.add("APPLICATION_CONTEXT('automotive design')")
        self.add(f"APPLICATION_PROTOCOL_DEFINITION('international standard',"
                 f"'automotive_design',2000,{app})")
        pctx = self.add(f"PRODUCT_CONTEXT('',{app},'mechanical')")
        dctx = self.add(f"PRODUCT_DEFINITION_CONTEXT('part definition',{app},'design')")
        prod = self.add(f"PRODUCT('{name}','{name}','',({pctx}))")
        form = self.add(f"PRODUCT_DEFINITION_FORMATION('','',{prod})")
        pdef = self.add(f"PRODUCT_DEFINITION('design','',{form},{dctx})")
        shape = self.add(f"PRODUCT_DEFINITION_SHAPE('','',{pdef})")
        origin = self.axis((0, 0, 0), (0, 0, 1), (1, 0, 0))
        members = ",".join([origin] + items)
        rep = self.add(f"ADVANCED_BREP_SHAPE_REPRESENTATION('{name}',({members}),{ctx})")
        self.add(f"SHAPE_DEFINITION_REPRESENTATION({shape},{rep})")
        data = "\n".join(f"#{i + 1}={line};" for i, line in enumerate(self.lines))
        return ("ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('quadsim test fixture'),'2;1');\n"
                f"FILE_NAME('{name}.step','2026-01-01T00:00:00',('quadsim'),(''),"
                "'scripts/make_step_fixture.py','','');\n"
                "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));\nENDSEC;\n"
                f"DATA;\n{data}\nENDSEC;\nEND-ISO-10303-21;\n")


def box_geometry(offset=(0.0, 0.0, 0.0)):
    """Corners (8, 3) mm and faces as corner indices, counter-clockwise seen from outside."""
    a, b, c = BOX
    corners = np.array([[x, y, z] for z in (0, c) for y in (0, b) for x in (0, a)]) + offset
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return corners, faces


def box_shell(step: Step, offset=(0.0, 0.0, 0.0), drop_top: bool = False) -> list[str]:
    corners, faces = box_geometry(offset)
    vertices = [step.vertex(p) for p in corners]
    edges: dict[tuple[int, int], str] = {}
    out = []
    for face in faces:
        if drop_top and face == (4, 5, 7, 6):
            continue
        oriented = []
        for i, j in zip(face, face[1:] + face[:1]):
            key = (min(i, j), max(i, j))
            if key not in edges:
                edges[key] = step.line_edge(vertices[key[0]], vertices[key[1]],
                                            corners[key[0]], corners[key[1]])
            oriented.append((edges[key], (i, j) == key))
        p = corners[list(face)]
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        normal /= np.linalg.norm(normal)
        x = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
        plane = step.add(f"PLANE('',{step.axis(p[0], normal, x)})")
        out.append(step.face(plane, oriented))
    return out


def solid(step: Step, faces: list[str], closed: bool = True) -> str:
    if closed:
        shell = step.add(f"CLOSED_SHELL('',({','.join(faces)}))")
        return step.add(f"MANIFOLD_SOLID_BREP('',{shell})")
    shell = step.add(f"OPEN_SHELL('',({','.join(faces)}))")
    return step.add(f"SHELL_BASED_SURFACE_MODEL('',({shell}))")


def cylinder(step: Step) -> str:
    r, h = CYLINDER
    v_bot, v_top = step.vertex((r, 0, 0)), step.vertex((r, 0, h))
    circles = []
    for v, z in ((v_bot, 0.0), (v_top, h)):
        circle = step.add(f"CIRCLE('',{step.axis((0, 0, z), (0, 0, 1), (1, 0, 0))},{r:.6f})")
        circles.append(step.add(f"EDGE_CURVE('',{v},{v},{circle},.T.)"))
    seam = step.line_edge(v_bot, v_top, (r, 0, 0), (r, 0, h))
    bottom = step.face(step.add(f"PLANE('',{step.axis((0, 0, 0), (0, 0, -1), (1, 0, 0))})"),
                       [(circles[0], False)])
    top = step.face(step.add(f"PLANE('',{step.axis((0, 0, h), (0, 0, 1), (1, 0, 0))})"),
                    [(circles[1], True)])
    surface = step.add(f"CYLINDRICAL_SURFACE('',{step.axis((0, 0, 0), (0, 0, 1), (1, 0, 0))},"
                       f"{r:.6f})")
    side = step.face(surface, [(circles[0], True), (seam, True), (circles[1], False),
                               (seam, False)])
    return solid(step, [bottom, top, side])


def box_stl() -> bytes:
    corners, faces = box_geometry()
    triangles = []
    for f in faces:
        triangles += [(f[0], f[1], f[2]), (f[0], f[2], f[3])]
    out = bytearray(b"quadsim box fixture, mm".ljust(80, b" "))
    out += struct.pack("<I", len(triangles))
    for tri in triangles:
        p = corners[list(tri)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n)
        out += struct.pack("<12fH", *n, *p.ravel(), 0)
    return bytes(out)


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    step = Step()
    (OUT / "box.step").write_text(step.text("box", [solid(step, box_shell(step))]))
    (OUT / "box.stl").write_bytes(box_stl())
    step = Step()
    (OUT / "cylinder.step").write_text(step.text("cylinder", [cylinder(step)]))
    step = Step()
    (OUT / "open_box.step").write_text(
        step.text("open_box", [solid(step, box_shell(step, drop_top=True), closed=False)]))
    step = Step()
    two = [solid(step, box_shell(step)), solid(step, box_shell(step, offset=(100.0, 0, 0)))]
    (OUT / "two_boxes.step").write_text(step.text("two_boxes", two))
    print(f"wrote box.step, box.stl, cylinder.step, open_box.step, two_boxes.step in {OUT}")


if __name__ == "__main__":
    main()
