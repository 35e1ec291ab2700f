"""The refine job: choose faces, refine them (SMA or VTA), and prove it: per-face numbers before/after, the mesh
checks before/after, and the thesis's comparison with uniform re-tessellations of the whole part (Tables 1, 2, 6)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from . import cusp
from .adaptive import adaptive_refine
from .analysis import (
    AnalysisParams,
    PlacedStl,
    analyze_mesh,
    face_chordal_errors,
    faces_section,
    place_user_stl,
    unmatched_issue,
)
from .cad import CadModel, read_cad
from .checks import check_mesh, manifold3d_accepts
from .convert import provenance, sha256_file
from .edge_curves import EdgeCurves
from .errors import AmprepError, ErrorCode
from .formats import CAD_FORMATS, sniff_path
from .io_stl import read_stl
from .mesh import Mesh
from .mesher import mesh_model
from .progress import Progress, ProgressFn
from .quality import regularity
from .report import mesh_section
from .sma import Ratios, Refinement, sma_output_size, sma_refine
from .surfaces import Surface, surface_of
from .tessellate import MeshParams
from .vta import vta_refine

METHODS = ("sma", "vta", "adaptive")
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
        if self.max_triangles < 1:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, "max_triangles must be ≥ 1")
        AnalysisParams(self.layer, self.build_dir, self.sample_order).validate()


@dataclass(frozen=True, eq=False)
class RefineResult:
    """The refined mesh in the user's frame (`mesh`), the one scored in the CAD's frame (`cad_mesh`), the mesh
    before, the report, and per-triangle chordal error of `mesh`."""

    mesh: Mesh
    cad_mesh: Mesh
    before: Mesh
    report: dict[str, Any]
    chordal: np.ndarray
    surfaces: dict[int, Surface] = field(default_factory=dict)
    faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def select_faces(faces_before: list[dict[str, Any]], params: RefineParams, n_faces: int) -> dict[int, str]:
    """face id → why it is refined."""
    if params.faces is not None:
        bad = [f for f in params.faces if not 0 <= f < n_faces]
        if bad:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"no face {bad[0]}: the part has faces 0..{n_faces - 1}")
        return {int(f): "named" for f in params.faces}
    thresholds = [(params.max_chordal, "chordal_error", "mean chordal error"),
                  (params.max_cusp, "cusp_height", "mean cusp height")]
    any_threshold = any(t is not None for t, _, _ in thresholds) or params.max_cylindricity is not None
    out: dict[int, str] = {}
    for f in faces_before:
        if f["surface_type"] in ("plane", "none") or not f["triangles"]:
            continue
        reasons = []
        for limit, key, label in thresholds:
            value = (f.get(key) or {}).get("mean")
            if limit is not None and value is not None and value > limit:
                reasons.append(f"{label} {value:.4g} > {limit:g} mm")
        cyl = f.get("cylindricity")
        if params.max_cylindricity is not None and cyl and cyl["zone"] > params.max_cylindricity:
            reasons.append(f"cylindricity {cyl['zone']:.4g} > {params.max_cylindricity:g} mm")
        if reasons:
            out[f["id"]] = "; ".join(reasons)
        elif not any_threshold:
            out[f["id"]] = "curved face (no threshold given: every curved face)"
    return out


def _stats(x: np.ndarray) -> dict[str, float] | None:
    x = x[np.isfinite(x)]
    return {"mean": float(x.mean()), "max": float(x.max())} if len(x) else None


def _mesh_summary(mesh: Mesh) -> dict[str, Any]:
    """The report's `mesh` keys (report.mesh_section) of the input mesh, and its binary STL size."""
    section = mesh_section(mesh, check_mesh(mesh), manifold3d_accepts(mesh))
    return section | {"file_size": STL_HEADER + STL_PER_TRIANGLE * mesh.n_triangles}


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

    chordal = _stats(ch[on])
    row = {"triangles": mesh.n_triangles, "file_size": STL_HEADER + STL_PER_TRIANGLE * mesh.n_triangles,
           "chordal_error": chordal, "profile_error": 2 * chordal["max"] if chordal else None,
           "cusp_height": cusp_mean(on), "part_chordal_error": _stats(ch),
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


def _refine(method: str, mesh: Mesh, faces: np.ndarray, surfaces: dict[int, Surface], params: RefineParams,
            iterations: int, curves: EdgeCurves | None = None, target: float | None = None) -> Refinement:
    if method == "sma":
        return sma_refine(mesh, faces, surfaces, Ratios.parse(params.ratios))
    if method == "adaptive":
        return adaptive_refine(mesh, faces, surfaces, target or 1.0, params.max_triangles,
                               max(params.sample_order, 3), curves=curves)
    return vta_refine(mesh, faces, surfaces, iterations, max(params.sample_order, 3))


def uniform_curve(model: CadModel, start: float, target_triangles: int, surfaces: dict[int, Surface],
                  faces: np.ndarray, params: RefineParams, mesh_params: MeshParams, max_steps: int = 12) -> list[dict[str, Any]]:
    """Uniform re-tessellations of the whole part from `start` down until one has at least target_triangles, so the
    refined file's size is bracketed; each scored like the refined mesh. Steps halve the tolerance until the count
    grows, then follow the power law n ∝ tol^−s fitted to the last two points (each step ×1/16 … ×1/1.5)."""
    rows: list[dict[str, Any]] = []
    prev: Mesh | None = None
    tol = start
    floor = 1e-4 * max(start, 1e-3)
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


def refine_file(path: str | Path, stl: str | Path | None = None, mesh_params: MeshParams = MeshParams(tolerance=0.2),
                params: RefineParams = RefineParams(), progress: ProgressFn | None = None) -> RefineResult:
    """Refine a CAD part's tessellation, or (with `stl`) the user's own STL placed on the CAD, and report."""
    params.validate()
    prog = Progress(progress)
    fmt = sniff_path(path)
    if fmt not in CAD_FORMATS:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"{params.method.upper()} refines faces of a CAD model: give "
                          "the STEP, IGES or BREP (and the STL with --stl); STL-only refinement is not available yet")
    prog("reading", 0.0)
    model = read_cad(path, fmt)
    info: dict[str, Any] = {"format": fmt, "sha256": sha256_file(path), "units": model.units, "solids": model.solids,
                            "faces": len(model.faces)}
    placed: PlacedStl | None = None
    if stl is not None:
        user = read_stl(stl)
        if user.n_triangles == 0:
            raise AmprepError(ErrorCode.EMPTY_MODEL, "the STL holds no triangles")
        placed = place_user_stl(model, user, mesh_params, prog.span(0.02, 0.4))
        mesh, surfaces = placed.mesh, placed.surfaces
        info.update(source="user_stl", stl_sha256=sha256_file(stl), stl_triangles=user.n_triangles)
        base_tol = None
    else:
        res = mesh_model(model, mesh_params, prog.span(0.02, 0.3))
        mesh = res.mesh
        surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
        base_tol = res.tolerance
        info.update(source="tessellation", tolerance=res.tolerance)
    n_faces = len(model.faces)
    ap = AnalysisParams(params.layer, params.build_dir, params.sample_order, bounding_box=False)
    quality = regularity(mesh.corners)
    ch0 = face_chordal_errors(mesh, surfaces, params.sample_order)
    before = faces_section(mesh, ch0, surfaces, ap, quality, n_faces)
    chosen = select_faces(before, params, n_faces)
    faces = np.array(sorted(chosen), dtype=np.int64)
    size = predicted_size(params.method, mesh, faces, params.iterations)
    if size > params.max_triangles:
        raise AmprepError(ErrorCode.OUTPUT_TOO_LARGE, f"{params.method.upper()} would output {size:,} triangles, over "
                          f"the limit of {params.max_triangles:,}: choose fewer faces, fewer iterations or a coarser input")
    curves = EdgeCurves(model) if placed is None else None  # a user's STL has no B-rep edges behind its vertices
    worst = max((before[f]["chordal_error"] or {}).get("max", 0.0) for f in faces) if len(faces) else 0.0
    target = params.target if params.target is not None else (0.1 * worst if worst > 0 else 1.0)
    prog("refining", 0.45)
    ref = _refine(params.method, mesh, faces, surfaces, params, params.iterations, curves, target)
    out = ref.mesh
    prog("scoring", 0.55)
    analysis = analyze_mesh(out, ap, surfaces, n_faces, info, None, prog.span(0.55, 0.6))
    after = analysis.report["faces"]
    ch1 = analysis.chordal
    refined = []
    for f in faces:
        b, a = before[f], after[f]
        cats = ref.categories.get(int(f))
        refined.append({"id": int(f), "surface_type": b["surface_type"], "reason": chosen[int(f)],
                        "triangles_before": b["triangles"], "triangles_after": a["triangles"],
                        "categories": {str(k): n for k, n in enumerate(cats)} if cats is not None else None,
                        "chordal_error_before": b["chordal_error"], "chordal_error_after": a["chordal_error"],
                        "cusp_height_before": b["cusp_height"], "cusp_height_after": a["cusp_height"],
                        "cylindricity_before": b["cylindricity"], "cylindricity_after": a["cylindricity"]})
    mesh_before, mesh_after = _mesh_summary(mesh), analysis.report["mesh"]
    mesh_after["file_size"] = STL_HEADER + STL_PER_TRIANGLE * out.n_triangles
    issues = analysis.report["issues"]
    if (mesh_before["boundary_edges"], mesh_before["nonmanifold_edges"]) != (mesh_after["boundary_edges"],
                                                                               mesh_after["nonmanifold_edges"]):
        issues.append({"code": "topology_changed", "severity": "error", "count": 1,
                       "message": "the refined mesh's boundary or non-manifold edges differ from the input's"})
    if placed is not None and placed.unmatched:
        issues.append(unmatched_issue(placed))
    if not len(faces):
        issues.append({"code": "nothing_to_refine", "severity": "info", "count": 0,
                       "message": "no face exceeds the thresholds: the mesh is returned unchanged"})
    comparison: dict[str, Any] | None = None
    if params.compare:
        prog("comparing with uniform tessellations", 0.6)
        box = params.compare_box
        this = {"label": params.method.upper()} | score_mesh(out, surfaces, faces, params, box)
        other_method = "vta" if params.method == "sma" else "sma"  # SMA is the reference for VTA and adaptive
        label = other_method.upper() + (f" ({params.compare_vta_iterations} iterations)" if other_method == "vta" else "")
        other_row: dict[str, Any] | None = None
        if predicted_size(other_method, mesh, faces, params.compare_vta_iterations) <= params.max_triangles:
            other = _refine(other_method, mesh, faces, surfaces, params, params.compare_vta_iterations, curves, target)
            other_row = {"label": label} | score_mesh(other.mesh, surfaces, faces, params, box)
        start = base_tol if base_tol is not None else float(mesh_params.tolerance)
        curve = uniform_curve(model, start, out.n_triangles, surfaces, faces, params, mesh_params) if len(faces) else []
        comparison = {"before": {"label": "input"} | score_mesh(mesh, surfaces, faces, params, box), "refined": this,
                      "other_method": other_row, "uniform": curve,
                      "note": "chordal_error, profile_error and cusp_height (t·|n·b|) over the refined faces; part_* "
                              "over the whole part (part_cusp_height_box: the thesis's bounding-box method); file_size "
                              "of a binary STL"}
    report = analysis.report
    report["params"] = {"method": params.method, "target": target if params.method == "adaptive" else None, "faces": list(params.faces) if params.faces is not None else None,
                        "max_chordal": params.max_chordal, "max_cusp": params.max_cusp,
                        "max_cylindricity": params.max_cylindricity, "layer": params.layer,
                        "build_dir": list(params.build_dir), "ratios": params.ratios, "iterations": params.iterations,
                        "sample_order": params.sample_order}
    report.update(method=params.method, mesh_before=mesh_before, refined_faces=refined, comparison=comparison,
                  issues=issues, provenance=provenance(mesh_params))
    user_frame = out
    if placed is not None:
        report["alignment"] = placed.alignment()
        R, t = np.asarray(placed.fit.rotation), np.asarray(placed.fit.translation)
        user_frame = replace(out, vertices=(out.vertices - t) @ R)  # x_user = Rᵀ (x_cad − t)
    prog("done", 1.0)
    return RefineResult(user_frame, out, mesh, report, ch1, surfaces, faces)
