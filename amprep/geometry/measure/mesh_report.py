"""The analysis report (schema amprep.report/1): mesh checks and the issues list built from them."""

from __future__ import annotations

from typing import Any

from amprep.geometry.core.checks import MeshChecks
from amprep.geometry.core.mesh import Mesh

SCHEMA = "amprep.report/1"


def mesh_section(mesh: Mesh, checks: MeshChecks, manifold3d: bool) -> dict[str, Any]:
    """The report's `mesh` object; watertight = our edge checks closed AND manifold3d accepts."""
    lo, hi = mesh.bbox()
    return {
        "triangles": checks.triangles, "vertices": checks.vertices,
        "watertight": bool(checks.closed and manifold3d), "closed_by_edges": checks.closed,
        "manifold3d": manifold3d, "boundary_edges": checks.boundary_edges,
        "nonmanifold_edges": checks.nonmanifold_edges, "misoriented_edges": checks.misoriented_edges,
        "degenerate_triangles": checks.degenerate_triangles, "duplicate_triangles": checks.duplicate_triangles,
        "shells": checks.shells, "volume": checks.volume, "area": checks.area,
        "bbox": {"min": [float(x) for x in lo], "max": [float(x) for x in hi]},
    }


def mesh_issues(checks: MeshChecks, manifold3d: bool, unmeshed_faces: int = 0) -> list[dict[str, Any]]:
    """One {code, severity, count, message} per defect kind found (empty for a clean closed mesh)."""
    found = [
        ("boundary_edges", "error", checks.boundary_edges, "edges used by one triangle: the mesh is open"),
        ("nonmanifold_edges", "error", checks.nonmanifold_edges, "edges shared by more than two triangles"),
        ("misoriented_edges", "error", checks.misoriented_edges, "neighbouring triangles with opposite orientation"),
        ("degenerate_triangles", "warning", checks.degenerate_triangles, "triangles of zero area"),
        ("duplicate_triangles", "warning", checks.duplicate_triangles, "triangles repeated on the same vertices"),
        ("unmeshed_faces", "error", unmeshed_faces, "CAD faces that got no triangles"),
    ]
    out = [{"code": c, "severity": s, "count": int(n), "message": m} for c, s, n, m in found if n]
    if checks.volume <= 0 and checks.closed:
        out.append({"code": "inside_out", "severity": "error", "count": 1,
                    "message": "the closed mesh has negative volume: its normals point inwards"})
    if checks.closed and not manifold3d:
        out.append({"code": "manifold3d_rejects", "severity": "error", "count": 1,
                    "message": "our edge checks find it closed but manifold3d rejects it"})
    if not checks.closed and manifold3d:
        out.append({"code": "checks_disagree", "severity": "info", "count": 1,
                    "message": "manifold3d accepts a mesh our edge checks find open or non-manifold"})
    return out
