"""Choose the faces to refine, refine them by a method, and score meshes for the before/after comparison with
uniform re-tessellations (thesis Tables 1, 2, 6)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.edge_curves import EdgeCurves
from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import Surface
from amprep.geometry.core.checks import check_mesh, manifold3d_accepts
from amprep.geometry.core.limits import MIN_TOLERANCE
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.measure import cusp
from amprep.geometry.measure.analysis import AnalysisParams, face_chordal_errors
from amprep.geometry.measure.report import FaceScore, Issue, MeshSection, Stats, mesh_section, stats_json
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.refine.adaptive import adaptive_refine
from amprep.geometry.refine.face_domain import FaceDomains
from amprep.geometry.refine.sma import Ratios, Refinement, sma_output_size, sma_refine
from amprep.geometry.refine.vta import vta_refine

METHODS = ("sma", "vta", "adaptive", "butterfly")  # butterfly: an STL alone (butterfly.py)


STL_HEADER, STL_PER_TRIANGLE = 84, 50  # binary STL bytes


@dataclass(frozen=True)
class RefineParams:
    """What to refine and how: `faces` named, else the faces over a threshold (mean chordal error, mean cusp height,
    cylindricity zone; non-planar faces only), else every curved face; SMA `ratios`; VTA `iterations`; `compare`
    adds the uniform re-tessellations and the other method's point."""

    method: str = "sma"
    faces: tuple[int, ...] | None = None
    max_chordal: float | None = None
    max_cusp: float | None = None
    max_cylindricity: float | None = None
    layer: float = 0.2
    build_dir: tuple[float, float, float] = (0.0, 0.0, 1.0)
    ratios: str = "3:4:3,3:4:3"
    iterations: int = 1
    target: float | None = None  # adaptive: chordal error to reach (default: a tenth of the chosen faces' worst)
    sample_order: int = 6
    compare: bool = True
    compare_vta_iterations: int = 3  # 3 rounds of 1 → 3 give 27× the triangles: SMA's size (27 + 2k per triangle)
    compare_box: bool = True  # the bounding-box cusp height of every compared mesh (slow on big parts)
    max_triangles: int = 10_000_000  # refuse (output_too_large) a refinement predicted to exceed this
    levels: int = 1  # butterfly: levels of 1-to-4 splitting (0: as many as max_triangles allows)
    max_edge: float | None = None  # butterfly: re-mesh on the limit surface to this edge length (mm) instead
    feature_angle: float = 30.0  # butterfly: dihedral angle (deg) over which an edge is a feature curve

    def validate(self) -> None:
        if self.method not in METHODS:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"method must be one of {', '.join(METHODS)}")
        Ratios.parse(self.ratios)
        for name in ("max_chordal", "max_cusp", "max_cylindricity"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise AmprepError(ErrorCode.INVALID_PARAMETER, f"{name} must be > 0")
        if not 1 <= self.iterations <= 50:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "iterations must be in 1..50")
        if self.target is not None and not self.target > 0:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "target must be > 0")
        if not 0 <= self.levels <= 6:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "levels must be in 0..6")
        if self.max_edge is not None and not self.max_edge > 0:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "max_edge must be > 0")
        if self.max_triangles < 1:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "max_triangles must be ≥ 1")
        AnalysisParams(self.layer, self.build_dir, self.sample_order).validate()


def select_faces(faces_before: list[FaceScore], params: RefineParams, n_faces: int) -> dict[int, str]:
    """face id → why it is refined."""
    if params.faces is not None:
        bad = [f for f in params.faces if not 0 <= f < n_faces]
        if bad:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"no face {bad[0]}: the part has faces 0..{n_faces - 1}")
        return {int(f): "named" for f in params.faces}
    any_threshold = any(t is not None for t in (params.max_chordal, params.max_cusp, params.max_cylindricity))
    out: dict[int, str] = {}
    for f in faces_before:
        if f.surface_type in ("plane", "none") or not f.triangles:
            continue
        reasons = []
        for limit, value, label in ((params.max_chordal, f.chordal_error, "mean chordal error"),
                                    (params.max_cusp, f.cusp_height, "mean cusp height")):
            if limit is not None and value is not None and value.mean > limit:
                reasons.append(f"{label} {value.mean:.4g} > {limit:g} mm")
        cyl = f.cylindricity
        if params.max_cylindricity is not None and cyl and cyl["zone"] > params.max_cylindricity:
            reasons.append(f"cylindricity {cyl['zone']:.4g} > {params.max_cylindricity:g} mm")
        if reasons:
            out[f.id] = "; ".join(reasons)
        elif not any_threshold:
            out[f.id] = "curved face (no threshold given: every curved face)"
    return out


def mesh_summary(mesh: Mesh) -> MeshSection:
    """The report's `mesh` section of the input mesh, with its binary STL size."""
    section = mesh_section(mesh, check_mesh(mesh), manifold3d_accepts(mesh))
    return section.with_extra(file_size=STL_HEADER + STL_PER_TRIANGLE * mesh.n_triangles)


def score_mesh(mesh: Mesh, surfaces: dict[int, Surface], faces: np.ndarray, params: RefineParams,
           box: bool = False) -> dict[str, Any]:
    """Triangles, binary STL size, chordal and profile error (2·max) and approximate cusp height on the chosen faces
    and the whole part; with `box`, the thesis's bounding-box cusp height of the whole part (its Tables 2 and 6)."""
    ch = face_chordal_errors(mesh, surfaces, params.sample_order)
    on = np.isin(mesh.face_ids, faces)
    corners = mesh.corners
    b = np.asarray(params.build_dir, float)
    c, counted = cusp.approximate(corners, params.layer, b)
    _, area = cusp.unit_normals(corners)

    def cusp_mean(sel: np.ndarray) -> float | None:
        w = area * counted * sel
        return float((c * w).sum() / w.sum()) if w.sum() > 0 else None

    chordal = Stats.of(ch[on])
    row = {"triangles": mesh.n_triangles, "file_size": STL_HEADER + STL_PER_TRIANGLE * mesh.n_triangles,
           "chordal_error": stats_json(chordal), "profile_error": 2 * chordal.max if chordal else None,
           "cusp_height": cusp_mean(on), "part_chordal_error": stats_json(Stats.of(ch)),
           "part_cusp_height": cusp_mean(np.ones(len(on), bool))}
    if box:
        row["part_cusp_height_box"] = cusp.bounding_box(corners, params.layer, b).summary()["mean"]
    return row


def predicted_size(method: str, mesh: Mesh, faces: np.ndarray, iterations: int) -> int:
    """Triangles a refinement will output (VTA: every chosen triangle split in three per iteration)."""
    if method == "sma":
        return sma_output_size(mesh, faces)
    if method == "adaptive":  # stops by itself before its budget
        return mesh.n_triangles
    n_sel = int(np.isin(mesh.face_ids, faces).sum())
    return mesh.n_triangles - n_sel + n_sel * 3**iterations


def refine_faces(method: str, mesh: Mesh, faces: np.ndarray, surfaces: dict[int, Surface], params: RefineParams,
            iterations: int, curves: EdgeCurves | None = None, target: float | None = None,
            domain: FaceDomains | None = None) -> Refinement:
    if method == "sma":
        return sma_refine(mesh, faces, surfaces, Ratios.parse(params.ratios))
    if method == "adaptive":
        return adaptive_refine(mesh, faces, surfaces, target or 1.0, params.max_triangles,
                               max(params.sample_order, 3), curves=curves, domain=domain)
    return vta_refine(mesh, faces, surfaces, iterations, max(params.sample_order, 3))


def uniform_curve(model: CadModel, start: float, target_triangles: int, surfaces: dict[int, Surface],
                  faces: np.ndarray, params: RefineParams, mesh_params: MeshParams, max_steps: int = 12) -> list[dict[str, Any]]:
    """Uniform re-tessellations of the whole part from `start` down until one has at least target_triangles, so the
    refined file's size is bracketed; each scored like the refined mesh. Steps halve the tolerance until the count
    grows, then follow the power law n ∝ tol^−s fitted to the last two points (each step ×1/16 … ×1/1.5)."""
    rows: list[dict[str, Any]] = []
    prev: Mesh | None = None
    tol = start
    floor = max(1e-4 * max(start, 1e-3), MIN_TOLERANCE)
    for _ in range(max_steps):
        res = mesh_model(model, replace(mesh_params, tolerance=tol, relative=None))
        same = prev is not None and prev.n_triangles == res.mesh.n_triangles and np.array_equal(prev.vertices, res.mesh.vertices)
        score = dict(rows[-1]) if same else score_mesh(res.mesh, surfaces, faces, params, params.compare_box)
        rows.append(score | {"label": f"uniform {tol:.4g} mm", "tolerance": tol})
        prev = res.mesh
        n = res.mesh.n_triangles
        if n >= target_triangles or tol <= floor:
            break
        factor = 0.5
        if len(rows) >= 2 and rows[-2]["triangles"] < n:
            slope = np.log(n / rows[-2]["triangles"]) / np.log(rows[-2]["tolerance"] / tol)
            wanted = (target_triangles * 1.1 / n) ** (-1.0 / max(slope, 0.25))
            factor = float(np.clip(wanted, 1 / 16, 1 / 1.5))
        tol = max(tol * factor, floor)
    return rows


def topology_issues(mesh_before: MeshSection, mesh_after: MeshSection) -> list[Issue]:
    """topology_changed when the refined mesh's boundary or non-manifold edge counts differ from the input's."""
    b, a = mesh_before.checks, mesh_after.checks
    if (b.boundary_edges, b.nonmanifold_edges) == (a.boundary_edges, a.nonmanifold_edges):
        return []
    return [Issue("topology_changed", "error", 1, "the refined mesh's boundary or non-manifold edges differ from the "
                  "input's")]


def refined_faces(faces: np.ndarray, before: list[FaceScore], after: list[FaceScore], chosen: dict[int, str],
                  ref: Refinement) -> list[dict[str, Any]]:
    """refined_faces[]: per refined face, why, triangles, SMA categories and the errors before and after."""
    out = []
    for f in faces:
        b, a = before[f], after[f]
        cats = ref.categories.get(int(f))
        out.append({"id": int(f), "surface_type": b.surface_type, "reason": chosen[int(f)],
                    "triangles_before": b.triangles, "triangles_after": a.triangles,
                    "categories": {str(k): n for k, n in enumerate(cats)} if cats is not None else None,
                    "chordal_error_before": stats_json(b.chordal_error),
                    "chordal_error_after": stats_json(a.chordal_error),
                    "cusp_height_before": stats_json(b.cusp_height), "cusp_height_after": stats_json(a.cusp_height),
                    "cylindricity_before": b.cylindricity, "cylindricity_after": a.cylindricity})
    return out


def compare(model: CadModel, mesh: Mesh, out: Mesh, faces: np.ndarray, surfaces: dict[int, Surface],
            params: RefineParams, mesh_params: MeshParams, start: float, curves: EdgeCurves | None,
            target: float) -> dict[str, Any]:
    """The comparison section: the input, the refined mesh, the other method (SMA, or VTA for SMA) and uniform
    re-tessellations from `start` mm down to the refined mesh's size, each scored by score_mesh."""
    box = params.compare_box
    this = {"label": params.method.upper()} | score_mesh(out, surfaces, faces, params, box)
    other_method = "vta" if params.method == "sma" else "sma"  # SMA is the reference for VTA and adaptive
    label = other_method.upper() + (f" ({params.compare_vta_iterations} iterations)" if other_method == "vta" else "")
    other_row: dict[str, Any] | None = None
    if predicted_size(other_method, mesh, faces, params.compare_vta_iterations) <= params.max_triangles:
        other = refine_faces(other_method, mesh, faces, surfaces, params, params.compare_vta_iterations, curves, target)
        other_row = {"label": label} | score_mesh(other.mesh, surfaces, faces, params, box)
    curve = uniform_curve(model, start, out.n_triangles, surfaces, faces, params, mesh_params) if len(faces) else []
    return {"before": {"label": "input"} | score_mesh(mesh, surfaces, faces, params, box), "refined": this,
            "other_method": other_row, "uniform": curve,
            "note": "chordal_error, profile_error and cusp_height (t·|n·b|) over the refined faces; part_* over the "
                    "whole part (part_cusp_height_box: the thesis's bounding-box method); file_size of a binary STL"}


def refine_params_section(params: RefineParams, target: float) -> dict[str, Any]:
    """The report's `params` of a refinement (target only for the adaptive method)."""
    return {"method": params.method, "target": target if params.method == "adaptive" else None,
            "faces": list(params.faces) if params.faces is not None else None,
            "max_chordal": params.max_chordal, "max_cusp": params.max_cusp,
            "max_cylindricity": params.max_cylindricity, "layer": params.layer,
            "build_dir": list(params.build_dir), "ratios": params.ratios, "iterations": params.iterations,
            "sample_order": params.sample_order}
