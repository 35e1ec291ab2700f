"""The one indexed mesh model shared by convert, analyze, refine and the writers."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

#: vertex_dim values: where a mesh vertex lies in the B-rep.
ON_BREP_VERTEX, ON_BREP_EDGE, IN_FACE, NO_TOPOLOGY = 0, 1, 2, -1


@dataclass(frozen=True)
class FaceInfo:
    """One CAD face: `surface_type` in plane|cylinder|cone|sphere|torus|bspline|bezier|revolution|extrusion|offset|other|none."""

    id: int
    surface_type: str
    solid: int = 0
    # occt | refined (OCCT's, mended where over tolerance) | fallback (our Delaunay) | quality (the quality mesher's
    # Delaunay) | lattice (its closed-form rows) | stored | stl
    meshed_by: str = "occt"


@dataclass(frozen=True, eq=False)
class Mesh:
    """Indexed triangle mesh with its CAD topology; arrays are never mutated in place.

    vertices: (n, 3) float64 mm · triangles: (m, 3) int64, counter-clockwise seen from outside ·
    face_ids: (m,) int32 CAD face per triangle (-1: none) · uv: (m, 3, 2) float64 surface parameters of
    each corner on its face, or None · vertex_dim: (n,) int8 0 B-rep vertex | 1 B-rep edge | 2 face
    interior | -1 unknown · vertex_entity: (n,) int32 index of that B-rep vertex, edge or face ·
    vertex_param: (n,) float64 parameter on the B-rep edge (nan elsewhere) · faces: FaceInfo per face id.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    face_ids: np.ndarray
    uv: np.ndarray | None = None
    vertex_dim: np.ndarray | None = None
    vertex_entity: np.ndarray | None = None
    vertex_param: np.ndarray | None = None
    faces: tuple[FaceInfo, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        n, m = len(self.vertices), len(self.triangles)
        if self.vertices.shape != (n, 3) or self.triangles.shape != (m, 3) or self.face_ids.shape != (m,):
            raise ValueError("mesh arrays have inconsistent shapes")
        if self.uv is not None and self.uv.shape != (m, 3, 2):
            raise ValueError("uv must be (m, 3, 2)")
        for a in (self.vertices, self.triangles, self.face_ids, self.uv, self.vertex_dim,
                  self.vertex_entity, self.vertex_param):
            if a is not None:
                a.flags.writeable = False

    @classmethod
    def from_arrays(cls, vertices: np.ndarray, triangles: np.ndarray) -> Mesh:
        """A mesh with no CAD topology (e.g. read from STL): face_ids all -1."""
        v = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        t = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1, 3)
        return cls(v, t, np.full(len(t), -1, np.int32))

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @property
    def corners(self) -> np.ndarray:
        """(m, 3, 3) float64 triangle corner coordinates."""
        return self.vertices[self.triangles]

    def bbox(self) -> tuple[np.ndarray, np.ndarray]:
        """(min (3,), max (3,)) of the vertices used by triangles."""
        if self.n_triangles == 0:
            z = np.zeros(3)
            return z, z
        mask = np.zeros(self.n_vertices, bool)
        mask[self.triangles] = True
        used = self.vertices[mask]
        return used.min(axis=0), used.max(axis=0)

    def with_arrays(self, **changes: object) -> Mesh:
        """A new mesh with some arrays replaced (inputs are never mutated)."""
        return replace(self, **changes)  # type: ignore[arg-type]

    def face_triangles(self, face_id: int) -> np.ndarray:
        """(k,) int64 indices of the triangles of one CAD face."""
        return np.flatnonzero(self.face_ids == face_id)

