"""The report's sections as typed values (schema amprep.report/1): each has to_json() giving its JSON object with
the fixed keys; modules pass these, not dicts read by string keys. The whole report is assembled by
analysis.Analysis.report."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from amprep.geometry.core.checks import MeshChecks, closed_by_position
from amprep.geometry.core.mesh import Mesh

SCHEMA = "amprep.report/1"


@dataclass(frozen=True)
class Stats:
    """{mean, max} of a measure over triangles (mm)."""

    mean: float
    max: float

    @classmethod
    def of(cls, x: np.ndarray) -> Stats | None:
        """Mean and max of the finite values of x (any shape), None when there are none."""
        x = x[np.isfinite(x)]
        return cls(float(x.mean()), float(x.max())) if len(x) else None

    def to_json(self) -> dict[str, float]:
        return {"mean": self.mean, "max": self.max}


def stats_json(s: Stats | None) -> dict[str, float] | None:
    return s.to_json() if s is not None else None


@dataclass(frozen=True)
class Issue:
    """One kind of defect found: a stable `code`, severity error | warning | info, how many, a sentence, and the CAD
    faces concerned when it is about faces."""

    code: str
    severity: str
    count: int
    message: str
    face_ids: tuple[int, ...] | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"code": self.code, "severity": self.severity, "count": self.count, "message": self.message}
        if self.face_ids is not None:
            out["face_ids"] = list(self.face_ids)
        return out


@dataclass(frozen=True)
class MeshSection:
    """The report's `mesh`: counts from our edge checks, manifold3d's verdict (watertight = both), volume, area, box;
    `defects` (analysis: boundary loops, non-manifold vertices, self-intersections, locations) and `extra` (e.g. a
    refinement's file_size, a conversion's float32-degenerate count) follow them in the JSON."""

    checks: MeshChecks
    manifold3d: bool
    bbox: tuple[tuple[float, ...], tuple[float, ...]]
    defects: dict[str, Any] | None = None
    extra: dict[str, Any] | None = None

    @property
    def watertight(self) -> bool:
        return bool(self.checks.closed and self.manifold3d)

    @property
    def triangles(self) -> int:
        return self.checks.triangles

    def with_extra(self, **values: Any) -> MeshSection:
        """This section with more keys after the others."""
        return replace(self, extra={**(self.extra or {}), **values})

    def with_position(self, joined: int, nonmanifold: int) -> MeshSection:
        """This section with what a reader that joins vertices by float32 position sees (core.checks.float32_joined:
        `joined` vertices, `nonmanifold` edges)."""
        return self.with_extra(float32_joined_vertices=joined, nonmanifold_edges_by_position=nonmanifold,
                               closed_by_position=closed_by_position(self.checks, nonmanifold))

    def to_json(self) -> dict[str, Any]:
        c = self.checks
        out = {
            "triangles": c.triangles, "vertices": c.vertices,
            "watertight": self.watertight, "closed_by_edges": c.closed,
            "manifold3d": self.manifold3d, "boundary_edges": c.boundary_edges,
            "nonmanifold_edges": c.nonmanifold_edges, "misoriented_edges": c.misoriented_edges,
            "degenerate_triangles": c.degenerate_triangles, "duplicate_triangles": c.duplicate_triangles,
            "shells": c.shells, "inside_out_shells": c.inside_out_shells, "volume": c.volume, "area": c.area,
            "bbox": {"min": list(self.bbox[0]), "max": list(self.bbox[1])},
        }
        return out | (self.defects or {}) | (self.extra or {})


@dataclass(frozen=True)
class FaceScore:
    """One CAD face's entry of faces[]: triangles, chordal error, profile error = 2·max chordal error, approximate
    cusp height, minimum-zone cylindricity (cylinders) and mean regularity per measure (None where not measured)."""

    id: int
    surface_type: str
    triangles: int
    chordal_error: Stats | None
    cusp_height: Stats | None
    cylindricity: dict[str, Any] | None
    regularity: dict[str, float] | None

    @property
    def profile_error(self) -> float | None:
        return 2 * self.chordal_error.max if self.chordal_error is not None else None

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "surface_type": self.surface_type, "triangles": self.triangles,
                "chordal_error": stats_json(self.chordal_error), "profile_error": self.profile_error,
                "cusp_height": stats_json(self.cusp_height), "cylindricity": self.cylindricity,
                "regularity": self.regularity}


def mesh_section(mesh: Mesh, checks: MeshChecks, manifold3d: bool) -> MeshSection:
    """The report's `mesh` section of a mesh; watertight = our edge checks closed AND manifold3d accepts."""
    lo, hi = mesh.bbox()
    return MeshSection(checks, manifold3d, (tuple(float(x) for x in lo), tuple(float(x) for x in hi)))


def mesh_issues(checks: MeshChecks, manifold3d: bool, unmeshed_faces: tuple[int, ...] = ()) -> list[Issue]:
    """One Issue per defect kind found (empty for a clean closed mesh); unmeshed_faces: ids of faces with no
    triangles."""
    found = [
        ("boundary_edges", "error", checks.boundary_edges, "edges used by one triangle: the mesh is open"),
        ("nonmanifold_edges", "error", checks.nonmanifold_edges, "edges shared by more than two triangles"),
        ("misoriented_edges", "error", checks.misoriented_edges, "neighbouring triangles with opposite orientation"),
        ("degenerate_triangles", "warning", checks.degenerate_triangles, "triangles of zero area"),
        ("duplicate_triangles", "warning", checks.duplicate_triangles, "triangles repeated on the same vertices"),
    ]
    out = [Issue(c, s, int(n), m) for c, s, n, m in found if n]
    if unmeshed_faces:
        out.append(Issue("unmeshed_faces", "error", len(unmeshed_faces), "CAD faces that got no triangles",
                         tuple(unmeshed_faces[:1000])))
    if checks.inside_out_shells or (checks.volume <= 0 and checks.closed):
        out.append(Issue("inside_out", "error", max(checks.inside_out_shells, 1),
                         "closed shells of negative volume that enclose no cavity: their normals point inwards"))
    if checks.closed and not manifold3d:
        out.append(Issue("manifold3d_rejects", "error", 1, "our edge checks find it closed but manifold3d rejects it"))
    if not checks.closed and manifold3d:
        out.append(Issue("checks_disagree", "info", 1,
                         "manifold3d accepts a mesh our edge checks find open or non-manifold"))
    return out
