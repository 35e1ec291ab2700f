"""Score a mesh: every number of the error report (checks, defects, regularity, cusp height, per-face chordal error
and cylindricity against the exact surfaces when the faces are known)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.core.checks import check_mesh, float32_joined, manifold3d_accepts
from amprep.geometry.core.compiled import compiled
from amprep.geometry.core.edges import edge_incidence
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import Progress, ProgressFn, checkpoint
from amprep.geometry.measure import cusp
from amprep.geometry.measure.chordal import barycentric_grid, triangle_chordal_error, worth_compiling
from amprep.geometry.measure.cylindricity import minimum_zone
from amprep.geometry.measure.defects import (
    MAX_PAIRS,
    boundary_loops,
    defect_locations,
    nonmanifold_vertices,
    self_intersections,
)
from amprep.geometry.measure.regularity import MEASURES, regularity_at, summarize
from amprep.geometry.measure.report import (
    SCHEMA,
    FaceScore,
    Issue,
    MeshSection,
    Stats,
    mesh_issues,
    mesh_section,
    stats_json,
)


@dataclass(frozen=True)
class AnalysisParams:
    """layer t (mm), build direction b, chordal sampling order k, cloud density (points/mm², None: (4/t)²),
    the number of defect locations and self-intersection examples kept, and whether to run the box method."""

    layer: float = 0.2
    build_dir: tuple[float, float, float] = (0.0, 0.0, 1.0)
    sample_order: int = 6
    cloud_density: float | None = None
    location_cap: int = 1000
    intersection_examples: int = 100
    bounding_box: bool = True

    def validate(self) -> None:
        if not self.layer > 0:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "layer must be > 0")
        if not np.linalg.norm(self.build_dir) > 0:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "build_dir must not be the zero vector")
        if not 1 <= self.sample_order <= 30:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "sample_order must be in 1..30")


@dataclass(eq=False)
class Analysis:
    """A scored mesh: the report's typed sections, and the per-triangle fields the viewer draws: chordal error (m,)
    (nan: unknown) and approximate cusp height (m,), on `mesh`; `box` the bounding-box method's boxes; `extra` the
    report keys a job adds after the others (alignment, provenance)."""

    mesh: Mesh
    chordal: np.ndarray
    cusp_height: np.ndarray
    box: cusp.BoxCusp | None
    input: dict[str, Any]
    mesh_section: MeshSection
    faces: list[FaceScore]
    chordal_error: Stats | None
    regularity: dict[str, Any]
    surface_types: dict[str, int]
    cusp: dict[str, Any]
    issues: list[Issue]
    params: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def report(self) -> dict[str, Any]:
        """The JSON report (report.json; keys fixed, schemas/report.schema.json)."""
        return {"schema": SCHEMA, "input": self.input, "mesh": self.mesh_section.to_json(),
                "faces": [f.to_json() for f in self.faces], "chordal_error": stats_json(self.chordal_error),
                "regularity": self.regularity, "surface_types": self.surface_types, "cusp_height": self.cusp,
                "issues": [i.to_json() for i in self.issues], "params": self.params} | self.extra


def face_chordal_errors(mesh: Mesh, surfaces: dict[int, Surface], order: int) -> np.ndarray:
    """(m,) chordal error ε_T = max_p |(S(u_p, v_p) − a)·n̂| of every triangle with a face, a surface and (u,v);
    nan elsewhere."""
    out = np.full(mesh.n_triangles, np.nan)
    if mesh.uv is None or not surfaces:
        return out
    corners = mesh.corners
    by_face = np.argsort(mesh.face_ids, kind="stable")
    bounds = np.searchsorted(mesh.face_ids[by_face], np.arange(max(surfaces) + 2))
    for fid, surf in surfaces.items():
        checkpoint()
        tris = by_face[bounds[fid]:bounds[fid + 1]]
        if len(tris) == 0:
            continue
        info = mesh.faces[fid] if fid < len(mesh.faces) else None
        if info is not None and info.meshed_by == "stored":
            continue
        out[tris] = triangle_chordal_error(corners[tris], mesh.uv[tris], surf, order, affine=surf.affine)
    return out


def _cylinder_cloud(corners: np.ndarray) -> np.ndarray:
    """Points on the triangles (order-4 barycentric grid: corners, edge points, interior), unique."""
    w = barycentric_grid(4)
    pts = np.einsum("pk,mkd->mpd", w, corners).reshape(-1, 3)
    return np.unique(pts.round(9), axis=0)


def faces_section(mesh: Mesh, chordal: np.ndarray, surfaces: dict[int, Surface], params: AnalysisParams,
                  quality: dict[str, np.ndarray], n_faces: int) -> list[FaceScore]:
    """faces[]: per CAD face id, surface type, triangles, chordal error {mean, max}, profile error = 2·max|d|,
    approximate cusp height {mean, max}, cylindricity (cylinders), regularity means."""
    b = np.asarray(params.build_dir, float)
    corners = mesh.corners
    c_tri, counted = cusp.approximate(corners, params.layer, b)
    _, area = cusp.unit_normals(corners)
    order = np.argsort(mesh.face_ids, kind="stable")
    bounds = np.searchsorted(mesh.face_ids[order], np.arange(n_faces + 1))
    out = []
    for fid in range(n_faces):
        checkpoint()
        tris = order[bounds[fid]:bounds[fid + 1]]
        stype = mesh.faces[fid].surface_type if fid < len(mesh.faces) else "none"
        w = (area[tris] * counted[tris])
        cusp_height = (Stats(float((c_tri[tris] * w).sum() / w.sum()), float(c_tri[tris][counted[tris]].max()))
                       if len(tris) and w.sum() > 0 else Stats(0.0, 0.0) if len(tris) else None)
        cylindricity = None
        surf = surfaces.get(fid)
        if stype == "cylinder" and len(tris) and surf is not None and surf.data:
            pts = _cylinder_cloud(corners[tris])
            if len(pts) >= 6:
                cylindricity = minimum_zone(pts, surf.data["origin"], surf.data["axis"]).as_dict()
        out.append(FaceScore(fid, stype, int(len(tris)), Stats.of(chordal[tris]) if len(tris) else None, cusp_height,
                             cylindricity, {k: float(quality[k][tris].mean()) for k in MEASURES} if len(tris) else None))
    return out


T = TypeVar("T")


def _checked(fn: Callable[..., T], *args: Any) -> T:
    """fn(*args) after the job's cancel check (core.progress.checkpoint)."""
    checkpoint()
    return fn(*args)


def analyze_mesh(mesh: Mesh, params: AnalysisParams = AnalysisParams(), surfaces: dict[int, Surface] | None = None,
                 n_faces: int = 0, input_info: dict[str, Any] | None = None, tolerance: float | None = None,
                 progress: ProgressFn | None = None) -> Analysis:
    """Score a mesh: checks, defects and their locations, regularity, cusp height (both methods), and, with the
    faces' exact surfaces, per-face chordal error and cylindricity."""
    params.validate()
    prog = Progress(progress)
    b = np.asarray(params.build_dir, float)
    b = b / np.linalg.norm(b)
    prog("checking the mesh", 0.0)
    checks = _checked(check_mesh, mesh)  # whole-mesh passes of a second or more each on millions of triangles:
    ok3d = _checked(manifold3d_accepts, mesh)  # a cancel is looked for between them
    inc = _checked(edge_incidence, mesh.triangles)
    loops = _checked(boundary_loops, mesh, inc)
    nmv = _checked(nonmanifold_vertices, mesh, inc)
    prog("self-intersections", 0.15)
    n_si, si_examples, si_complete = self_intersections(mesh, params.intersection_examples,
                                                         prog.span(0.15, 0.35))
    by_position = _checked(float32_joined, mesh, checks.nonmanifold_edges)
    section = replace(mesh_section(mesh, checks, ok3d).with_position(*by_position), defects={
        "boundary_loops": {"count": len(loops), "total_length": float(sum(loops)), "lengths": loops[:100]},
        "nonmanifold_vertices": int(len(nmv)),
        "self_intersections": {"count": n_si, "examples": si_examples.tolist(), "complete": si_complete},
        "locations": _checked(defect_locations, mesh, inc, nmv, params.location_cap),
    })
    prog("regularity", 0.35)
    q = regularity_at(mesh.vertices, mesh.triangles)
    summary = summarize(q)
    prog("chordal error", 0.4)
    with compiled(worth_compiling(mesh.n_triangles, params.sample_order)):  # decided by the mesh, not by timing
        chordal = face_chordal_errors(mesh, surfaces or {}, params.sample_order)
    prog("cusp height", 0.6)
    c_tri, counted = cusp.approximate(mesh.corners, params.layer, b)
    box = (cusp.bounding_box(mesh.corners, params.layer, b, params.cloud_density, progress=prog.span(0.6, 0.85))
           if params.bounding_box else None)
    prog("per-face report", 0.85)
    has_cad = surfaces is not None
    faces = faces_section(mesh, chordal, surfaces or {}, params, q, n_faces) if has_cad else []
    types: dict[str, int] = {}
    for f in faces:
        types[f.surface_type] = types.get(f.surface_type, 0) + f.triangles
    issues = mesh_issues(checks, ok3d, tuple(f.id for f in faces if f.triangles == 0))
    if n_si:
        issues.append(Issue("self_intersections", "error", n_si, "pairs of triangles that cross each other"))
    if not si_complete:
        issues.append(Issue("self_intersections_incomplete", "warning", 1, "the self-intersection test stopped after "
                            f"{MAX_PAIRS:,} pairs of overlapping triangles (a triangle soup?): the count is a lower bound"))
    if len(nmv):
        issues.append(Issue("nonmanifold_vertices", "error", int(len(nmv)),
                            "vertices where separate fans of triangles touch (bow-ties)"))
    if not has_cad:
        issues.append(Issue("chordal_error_unavailable", "info", 1,
                            "no CAD model: the distance to the design surface cannot be measured"))
    elif tolerance is not None:
        over = [f.id for f in faces if f.chordal_error and f.chordal_error.max > tolerance * (1 + 1e-9)]
        if over:
            issues.append(Issue("chordal_error_over_tolerance", "warning", len(over),
                                f"faces whose chordal error exceeds {tolerance:g} mm", tuple(over[:1000])))
    cusp_section = {"layer": params.layer, "build_direction": [float(x) for x in b],
                    "approximate": cusp.approximate_summary(mesh.corners, params.layer, b),
                    "bounding_box": box.summary() if box is not None else None}
    used = {"layer": params.layer, "build_dir": list(params.build_dir), "sample_order": params.sample_order,
            "cloud_density": box.density if box is not None else params.cloud_density}
    prog("done", 1.0)
    return Analysis(mesh, chordal, np.where(counted, c_tri, 0.0), box, input_info or {}, section, faces,
                    Stats.of(chordal) if has_cad else None, summary.as_dict(), types, cusp_section, issues, used)
