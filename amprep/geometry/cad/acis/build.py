"""OCCT shapes from decoded ACIS entities: one solid per lump, faces sharing their edges by topology.

Each ACIS edge becomes one TopoDS_Edge on its exact curve between its two vertices, shared by both faces; each
face a TopoDS_Face on its exact surface bounded by its loops in coedge order. ACIS keeps a face's loops
counter-clockwise about the face's normal (the surface normal, negated when the face is `reversed`): where that
normal is opposite to the OCCT surface's own, the face is built on the surface with its wires reversed and then
reversed itself, so every edge keeps the direction its coedge gives it. OCCT's shape healing then adds the curves
in each face's parameter space, the seams of closed surfaces (ACIS has none) and the degenerate edges at poles and
apexes, and orients each shell outward. Surfaces and curves with no exact or stored form are `Unsupported`: the
faces on them are left out and listed, never a silent hole.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from OCP.BRep import BRep_Builder
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakeVertex
from OCP.Geom import (
    Geom_BSplineCurve,
    Geom_BSplineSurface,
    Geom_Circle,
    Geom_ConicalSurface,
    Geom_Curve,
    Geom_CylindricalSurface,
    Geom_Ellipse,
    Geom_Line,
    Geom_Plane,
    Geom_SphericalSurface,
    Geom_Surface,
    Geom_SurfaceOfLinearExtrusion,
    Geom_ToroidalSurface,
)
from OCP.GeomAPI import GeomAPI_ProjectPointOnCurve
from OCP.gp import gp_Ax2, gp_Ax3, gp_Dir, gp_Pnt
from OCP.TColgp import TColgp_Array1OfPnt, TColgp_Array2OfPnt
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal, TColStd_Array2OfReal
from OCP.TopoDS import (
    TopoDS_Edge,
    TopoDS_Face,
    TopoDS_Shell,
    TopoDS_Solid,
    TopoDS_Vertex,
    TopoDS_Wire,
)

from amprep.geometry.cad.acis.checks import Unsupported, check_on_curve, check_vertices_on
from amprep.geometry.cad.acis.entities import Cursor, Model
from amprep.geometry.cad.acis.pcurves import attach, stored_pcurve
from amprep.geometry.cad.acis.records import Flag, fail
from amprep.geometry.cad.acis.splines import BSplineData, find_block, read_block
from amprep.geometry.cad.occt_arrays import to_array1

TOL = 1e-7  # mm-free: ACIS's resabs is 1e-6 in the file's units; OCCT's healing widens where needed


@dataclass
class Built:
    """(body record, solid) of every lump with faces, and the faces left out: [{"face", "surface", "why"}]."""

    shapes: list[object] = field(default_factory=list)
    skipped: list[dict[str, object]] = field(default_factory=list)


def _unit(v: tuple[float, float, float], where: str) -> gp_Dir:
    n = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    if not n > 1e-12:
        raise fail(f"{where}: a zero direction vector")
    return gp_Dir(v[0] / n, v[1] / n, v[2] / n)


def _norm(v: tuple[float, float, float]) -> float:
    return math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)


def bspline_curve(d: BSplineData) -> Geom_BSplineCurve:
    poles = TColgp_Array1OfPnt(1, len(d.poles))
    for i, p in enumerate(d.poles.tolist(), 1):
        poles.SetValue(i, gp_Pnt(*p))
    knots = to_array1(d.knots[0], TColStd_Array1OfReal)
    mults = to_array1(d.mults[0], TColStd_Array1OfInteger)
    if d.weights is None:
        return Geom_BSplineCurve(poles, knots, mults, d.degrees[0])
    return Geom_BSplineCurve(poles, to_array1(d.weights, TColStd_Array1OfReal), knots, mults, d.degrees[0])


def bspline_surface(d: BSplineData) -> Geom_BSplineSurface:
    nv, nu = d.poles.shape[:2]
    poles = TColgp_Array2OfPnt(1, nu, 1, nv)
    for v in range(nv):
        for u, p in enumerate(d.poles[v].tolist()):
            poles.SetValue(u + 1, v + 1, gp_Pnt(*p))
    ku, kv = (to_array1(k, TColStd_Array1OfReal) for k in d.knots)
    mu, mv = (to_array1(m, TColStd_Array1OfInteger) for m in d.mults)
    if d.weights is None:
        return Geom_BSplineSurface(poles, ku, kv, mu, mv, d.degrees[0], d.degrees[1])
    w = TColStd_Array2OfReal(1, nu, 1, nv)
    for v in range(nv):
        for u, x in enumerate(d.weights[v].tolist()):
            w.SetValue(u + 1, v + 1, x)
    return Geom_BSplineSurface(poles, w, ku, kv, mu, mv, d.degrees[0], d.degrees[1])


class Builder:
    """Builds the bodies of a Model; edges and vertices are made once and shared."""

    def __init__(self, model: Model) -> None:
        self.m = model
        self._vertex: dict[int, tuple[TopoDS_Vertex, gp_Pnt]] = {}
        self._edge: dict[int, tuple[TopoDS_Edge, bool] | None] = {}
        self._curve: dict[int, Geom_Curve] = {}
        self._surface: dict[int, tuple[Geom_Surface, bool]] = {}
        self._subtypes: list[tuple[int, int]] | None = None
        self._owned: set[int] = set()  # lumps, shells, faces and coedges placed: each belongs to one owner
        self._pcurves: list[tuple[TopoDS_Edge, int, int]] = []  # the face being built: edges, pcurves, records
        self.pcurves_used = 0

    # ------------------------------------------------------------ chains

    def chain(self, first: int, step, what: str, ring: bool = False) -> Iterator[int]:  # type: ignore[no-untyped-def]
        """first, step(first), … until -1 (or back to first, for a `ring` of coedges); a chain that comes back on
        itself otherwise is a reference cycle: unreadable_cad."""
        seen: set[int] = set()
        i = first
        while i != -1:
            if i in seen:
                if ring and i == first:
                    return
                raise fail(f"the {what} chain from ${first} loops back on ${i}")
            seen.add(i)
            if not ring:
                if i in self._owned:
                    raise fail(f"${i} ({what}) is claimed by two owners")
                self._owned.add(i)
            yield i
            i = step(i)

    # ------------------------------------------------------------ geometry

    def _subtype_tokens(self, c: Cursor) -> list:  # type: ignore[type-arg]
        tokens = c.subtype()
        if tokens[:1] == ["ref"]:
            return self._subtype_ref(int(tokens[1]), c.where)
        return tokens

    def _subtype_ref(self, n: int, where: str) -> list:  # type: ignore[type-arg]
        """Subtype n of the file (subtypes numbered as written, nested ones too, `ref` ones not counted)."""
        if self._subtypes is None:
            table: list[tuple[int, int]] = []
            for r in range(len(self.m.records)):
                toks = self.m.records.tokens(r)
                for k, t in enumerate(toks):
                    if t == "{" and not (k + 1 < len(toks) and toks[k + 1] == "ref"):
                        table.append((r, k))
            self._subtypes = table
        if not 0 <= n < len(self._subtypes):
            raise fail(f"{where}: subtype reference {n} outside the file's {len(self._subtypes)} subtypes")
        r, k = self._subtypes[n]
        c = Cursor(self.m.records.tokens(r), f"subtype {n}", k)
        tokens = c.subtype()
        if tokens[:1] == ["ref"]:
            raise fail(f"{where}: a subtype reference to a reference")
        return tokens

    def curve(self, i: int) -> Geom_Curve:
        got = self._curve.get(i)
        if got is None:
            got = self._curve[i] = self._make_curve(i)
        return got

    def _make_curve(self, i: int) -> Geom_Curve:
        name, c = self.m.geometry(i)
        if name == "straight-curve":
            root, d = c.vec(), c.vec()
            return Geom_Line(gp_Pnt(*root), _unit(d, c.where))
        if name == "ellipse-curve":
            centre, normal, major = c.vec(), c.vec(), c.vec()
            ratio = c.num()
            r, n = _norm(major), _unit(normal, c.where)
            if not r > 0 or not ratio > 0:
                raise fail(f"{c.where}: an ellipse with a zero axis")
            x = _unit(major, c.where)
            if abs(ratio - 1.0) < 1e-12:
                return Geom_Circle(gp_Ax2(gp_Pnt(*centre), n, x), r)
            if ratio < 1.0:
                return Geom_Ellipse(gp_Ax2(gp_Pnt(*centre), n, x), r, r * ratio)
            y = n.Crossed(x)  # minor longer than major: OCCT's x axis is the longer one, still counter-clockwise
            return Geom_Ellipse(gp_Ax2(gp_Pnt(*centre), n, y), r * ratio, r)
        if name.endswith("intcurve-curve"):
            c.flag("reversed", "forward")
            tokens = self._subtype_tokens(c)
            k = find_block(tokens, surface=False)
            if k is None:
                raise Unsupported(name, f"{tokens[0] if tokens else 'empty'} stores no approximation")
            return bspline_curve(read_block(tokens, k, False, c.where))
        raise Unsupported(name)

    def surface(self, i: int, wires: list[TopoDS_Wire]) -> tuple[Geom_Surface, bool]:
        """(OCCT surface, flipped): flipped when ACIS's surface normal is opposite to the OCCT surface's; `wires`,
        the face's, bound the B-spline an elliptical cone becomes (and it is not shared)."""
        got = self._surface.get(i)
        if got is None:
            got = self._make_surface(i, wires)
            if not isinstance(got[0], Geom_BSplineSurface) or self.m.name(i) != "cone-surface":
                self._surface[i] = got
        return got

    def _make_surface(self, i: int, wires: list[TopoDS_Wire]) -> tuple[Geom_Surface, bool]:
        name, c = self.m.geometry(i)
        if name == "plane-surface":
            root, normal, udir = c.vec(), c.vec(), c.vec()
            n = _unit(normal, c.where)
            try:
                ax = gp_Ax3(gp_Pnt(*root), n, _unit(udir, c.where))
            except Exception:  # noqa: BLE001 - u direction parallel to the normal: any x axis will do
                ax = gp_Ax3(gp_Pnt(*root), n)
            return Geom_Plane(ax), False
        if name == "cone-surface":
            return self._cone(c, wires)
        if name == "sphere-surface":
            centre, radius, udir, pole = c.vec(), c.num(), c.vec(), c.vec()
            if radius == 0:
                raise fail(f"{c.where}: a sphere of radius 0")
            ax = gp_Ax3(gp_Pnt(*centre), _unit(pole, c.where), _unit(udir, c.where))
            return Geom_SphericalSurface(ax, abs(radius)), radius < 0
        if name == "torus-surface":
            centre, axis, major, minor, udir = c.vec(), c.vec(), c.num(), c.num(), c.vec()
            if minor == 0 or major <= -abs(minor):
                raise fail(f"{c.where}: a torus with no surface (minor radius 0, or a lemon of no thickness)")
            ax = gp_Ax3(gp_Pnt(*centre), _unit(axis, c.where), _unit(udir, c.where))
            if major >= abs(minor):
                return Geom_ToroidalSurface(ax, major, abs(minor)), minor < 0
            return spindle_torus(ax, major, minor)
        if name == "spline-surface":
            rev = c.flag("reversed", "forward")
            tokens = self._subtype_tokens(c)
            k = find_block(tokens, surface=True)
            if k is None:
                kind = str(tokens[0]) if tokens else "empty"
                raise Unsupported(f"spline-surface ({kind})", "no stored approximation")
            return bspline_surface(read_block(tokens, k, True, c.where)), rev
        raise Unsupported(name)

    def _cone(self, c: Cursor, wires: list[TopoDS_Wire]) -> tuple[Geom_Surface, bool]:
        """ACIS cone: base ellipse (centre, axis, major axis vector, ratio), sine and cosine of the half angle
        (cosine < 0: the axis runs the other way), an optional u scale, and its reversal word; an elliptical cone
        is bounded by the face's `wires` (elliptical_cone)."""
        centre, axis, major = c.vec(), c.vec(), c.vec()
        ratio = c.num()
        nxt = c.peek()
        if isinstance(nxt, Flag) or nxt in ("I", "F"):  # the profile's interval (400 and later)
            c.bound(), c.bound()
        sine, cosine = c.num(), c.num()
        if c.number_next():
            c.num()  # u parameter scale (400 and later; some writers leave it out)
        rev = c.flag("reversed", "forward")
        r = _norm(major)
        if not r > 0 or not ratio > 0 or abs(sine * sine + cosine * cosine - 1) > 1e-6 or abs(cosine) < 1e-12:
            raise fail(f"{c.where}: a cone with a zero radius or an invalid half angle")
        z = _unit(axis, c.where)
        if cosine < 0:
            z = z.Reversed()
        x = _unit(major, c.where)
        ax = gp_Ax3(gp_Pnt(*centre), z, x)
        if abs(sine) < 1e-12:
            if abs(ratio - 1) < 1e-12:
                return Geom_CylindricalSurface(ax, r), rev
            a2 = gp_Ax2(gp_Pnt(*centre), z, x) if ratio < 1 else gp_Ax2(gp_Pnt(*centre), z, z.Crossed(x))
            ell = Geom_Ellipse(a2, max(r, r * ratio), min(r, r * ratio))
            return Geom_SurfaceOfLinearExtrusion(ell, z), rev
        cone = Geom_ConicalSurface(ax, math.atan2(sine, abs(cosine)), r)
        if abs(ratio - 1) > 1e-12:
            return elliptical_cone(cone, ratio, wires), rev
        return cone, rev

    # ------------------------------------------------------------ topology

    def vertex(self, i: int) -> tuple[TopoDS_Vertex, gp_Pnt]:
        got = self._vertex.get(i)
        if got is None:
            p = gp_Pnt(*self.m.point(self.m.vertex(i).point))
            got = self._vertex[i] = (BRepBuilderAPI_MakeVertex(p).Vertex(), p)
        return got

    def edge(self, i: int) -> tuple[TopoDS_Edge, bool] | None:
        """(edge along its curve, same direction as ACIS's edge), or None for an edge with no curve (a pole)."""
        if i in self._edge:
            return self._edge[i]
        e = self.m.edge(i)
        if e.curve == -1:
            self._edge[i] = None
            return None
        curve = self.curve(e.curve)
        first, last = (e.end, e.start) if e.reversed else (e.start, e.end)
        (v1, p1), (v2, p2) = self.vertex(first), self.vertex(last)
        a, b = _parameter(curve, p1), _parameter(curve, p2)
        check_on_curve(curve, a, b, p1, p2, i)
        if curve.IsPeriodic():
            period = curve.Period()
            span = (b - a) % period
            if first == last or span < 1e-9 * period:
                span = period
            b = a + span
        elif first == last and curve.IsClosed():
            a, b = curve.FirstParameter(), curve.LastParameter()
        along = True
        if b < a:
            a, b, v1, v2, along = b, a, v2, v1, False
        if b - a <= 1e-12:
            raise fail(f"edge ${i}: its vertices meet on its curve (a zero-length edge)")
        mk = BRepBuilderAPI_MakeEdge(curve, v1, v2, a, b)
        if not mk.IsDone():
            raise fail(f"edge ${i}: OCCT could not build it on its curve (error {int(mk.Error())})")
        built = (mk.Edge(), along != e.reversed)
        self._edge[i] = built
        return built

    def wire(self, loop: int) -> TopoDS_Wire:
        bb = BRep_Builder()
        w = TopoDS_Wire()
        bb.MakeWire(w)
        first = self.m.loop(loop).coedge
        for ce in self.chain(first, lambda k: self.m.coedge(k).next, "coedge", ring=True):
            if ce in self._owned:
                raise fail(f"coedge ${ce} is in two loops")
            self._owned.add(ce)
            co = self.m.coedge(ce)
            got = self.edge(co.edge)
            if got is None:
                continue
            edge, same = got
            bb.Add(w, edge if same != co.reversed else edge.Reversed())
            self._pcurves.append((edge, co.pcurve, co.edge))
        return w

    def face(self, i: int) -> TopoDS_Face:
        f = self.m.face(i)
        self._pcurves = []
        wires = [self.wire(lp) for lp in self.chain(f.loop, lambda k: self.m.loop(k).next, "loop")]
        surface, flipped = self.surface(f.surface, wires)
        flip = f.reversed != flipped
        bb = BRep_Builder()
        face = TopoDS_Face()
        if wires:
            bb.MakeFace(face, surface, TOL)
        else:  # a face on a whole closed surface (a ball, a lemon): its natural bounds
            face = BRepBuilderAPI_MakeFace(surface, TOL).Face()
        for w in wires:
            bb.Add(face, w.Reversed() if flip else w)
        if wires:  # natural bounds lie on their surface
            check_vertices_on(surface, face, self.m.name(f.surface), i)
        if isinstance(surface, Geom_BSplineSurface) and self.m.name(f.surface) == "spline-surface":
            self._attach_pcurves(face, surface)
        return face.Reversed() if flip else face  # type: ignore[return-value]

    def _attach_pcurves(self, face: TopoDS_Face, surface: Geom_BSplineSurface) -> None:
        """The face's stored pcurves on its edges where they fit (pcurves.py); an edge met twice (a slit) is left
        to the healing, which knows its two pcurves."""
        counts: dict[int, int] = {}
        for _, _, record in self._pcurves:
            counts[record] = counts.get(record, 0) + 1
        for edge, pc, record in self._pcurves:
            if pc == -1 or counts[record] != 1:
                continue
            data = stored_pcurve(self.m, pc)
            if data is not None and attach(edge, face, surface, data):
                self.pcurves_used += 1

    def body(self, i: int, out: Built) -> None:
        b = self.m.body(i)
        bb = BRep_Builder()
        for lump in self.chain(b.lump, lambda k: self.m.lump(k).next, "lump"):
            shells = []
            for sh in self.chain(self.m.lump(lump).shell, lambda k: self.m.shell(k).next, "shell"):
                shell = TopoDS_Shell()
                bb.MakeShell(shell)
                n = 0
                for fi in self.chain(self.m.shell(sh).face, lambda k: self.m.face(k).next, "face"):
                    try:
                        bb.Add(shell, self.face(fi))
                        n += 1
                    except Unsupported as exc:
                        out.skipped.append({"face": fi, "surface": exc.kind, "why": exc.detail or "not supported"})
                if n:
                    shells.append(shell)
            if shells:
                solid = TopoDS_Solid()
                bb.MakeSolid(solid)
                for s in shells:
                    bb.Add(solid, s)
                out.shapes.append((i, solid))


def spindle_torus(ax: gp_Ax3, major: float, minor: float) -> tuple[Geom_Surface, bool]:
    """ACIS's apple (0 ≤ major < |minor|) and lemon (−|minor| < major < 0) tori: the arc of the profile circle
    (centre at `major` on the x axis, radius |minor|, in the xz plane) on the far side of the axis from −x, between
    its two crossings of the axis, revolved about it; flipped when OCCT's normal there runs against ACIS's (away
    from the profile's centre, toward it when minor < 0)."""
    from OCP.Geom import Geom_SurfaceOfRevolution, Geom_TrimmedCurve
    from OCP.gp import gp_Ax1, gp_Vec

    r = abs(minor)
    o, x, z = ax.Location(), ax.XDirection(), ax.Direction()
    cp = o.Translated(gp_Vec(x).Multiplied(major))
    circle = Geom_Circle(gp_Ax2(cp, ax.YDirection().Reversed(), x), r)  # cp + r cos t x + r sin t z
    t0 = math.acos(max(-1.0, min(1.0, -major / r)))
    surface = Geom_SurfaceOfRevolution(Geom_TrimmedCurve(circle, -t0, t0), gp_Ax1(o, z))
    p, du, dv = gp_Pnt(), gp_Vec(), gp_Vec()
    surface.D1(0.0, 0.0, p, du, dv)
    outward = gp_Vec(x).Multiplied(1.0 if minor > 0 else -1.0)  # at t = 0 the point is cp + r x
    return surface, du.Crossed(dv).Dot(outward) < 0


def elliptical_cone(cone: Geom_ConicalSurface, ratio: float, wires: list[TopoDS_Wire]) -> Geom_BSplineSurface:
    """ACIS's elliptical cone, the circular `cone` scaled by `ratio` along its y axis: the cone trimmed to the
    axial span of the face's wires (5 % more each way, never past the apex), converted exactly to a rational
    B-spline, its poles scaled (an affine map of a rational B-spline's poles maps the surface exactly)."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Geom import Geom_RectangularTrimmedSurface
    from OCP.GeomConvert import GeomConvert
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    ax = cone.Position()
    o, z, y = ax.Location(), ax.Direction(), ax.YDirection()
    alpha, r = cone.SemiAngle(), cone.RefRadius()
    heights = []
    for w in wires:
        ex = TopExp_Explorer(w, TopAbs_EDGE)
        while ex.More():
            c = BRepAdaptor_Curve(TopoDS.Edge_s(ex.Current()))
            for t in np.linspace(c.FirstParameter(), c.LastParameter(), 9):
                p = c.Value(float(t))
                heights.append((p.X() - o.X()) * z.X() + (p.Y() - o.Y()) * z.Y() + (p.Z() - o.Z()) * z.Z())
            ex.Next()
    if not heights:
        raise Unsupported("cone-surface", "an elliptical cone face with no boundary")
    v = np.array(heights) / math.cos(alpha)
    pad = 0.05 * float(np.ptp(v)) + 1e-6 * r
    v0, v1 = float(v.min()) - pad, float(v.max()) + pad
    if math.sin(alpha) < 0:
        v1 = min(v1, -r / math.sin(alpha))
    elif math.sin(alpha) > 0:
        v0 = max(v0, -r / math.sin(alpha))
    bs = GeomConvert.SurfaceToBSplineSurface_s(Geom_RectangularTrimmedSurface(cone, 0.0, 2 * math.pi, v0, v1))
    for i in range(1, bs.NbUPoles() + 1):
        for j in range(1, bs.NbVPoles() + 1):
            p = bs.Pole(i, j)
            d = (p.X() - o.X()) * y.X() + (p.Y() - o.Y()) * y.Y() + (p.Z() - o.Z()) * y.Z()
            s = (ratio - 1.0) * d
            bs.SetPole(i, j, gp_Pnt(p.X() + s * y.X(), p.Y() + s * y.Y(), p.Z() + s * y.Z()))
    return bs


def _parameter(curve: Geom_Curve, p: gp_Pnt) -> float:
    """The parameter of p's nearest point on curve (p is an edge's vertex: on the curve to ACIS's tolerance)."""
    proj = GeomAPI_ProjectPointOnCurve(p, curve)
    if proj.NbPoints() == 0:
        raise fail("a vertex that cannot be placed on its edge's curve")
    return float(proj.LowerDistanceParameter())


def bodies(model: Model) -> list[int]:
    """Record indices of the file's bodies (every `body` record: ACIS writes them first)."""
    return [i for i, n in enumerate(model.records.names) if n == "body"]


__all__ = ["Builder", "Built", "Unsupported", "bodies"]
