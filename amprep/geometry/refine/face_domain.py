"""Where a face's trimmed (u,v) domain is: its wires as closed polygons in (u,v) (the mesher's boundary loops, the
edges discretised at the refinement's target or finer), so a refinement puts no point on a face's surface beyond its
trim: a coarse STL triangle whose corners lie on a face can have an edge whose (u,v) midpoint does not (CTC-02's
fillets, mitred where two meet: their (u,v) boundary there is a curve, and a chord across it leaves the face)."""

from __future__ import annotations

import numpy as np

from amprep.errors import AmprepError
from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import nearest_copy
from amprep.geometry.cad.topology import Topology
from amprep.geometry.meshing.face_mesher import boundary_loops
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.uv_cdt import inside_loops

#: the loops' edges are discretised at most this far (mm) from the exact edges: a point a few µm beyond a trim is off
#: the face (CTC-02's mitred fillets: split points 5–10 µm beyond it crossed the next fillet's triangles)
CHORD = 1e-3


class FaceDomains:
    """Point-in-domain tests on a model's faces, their loops at the chord `tolerance` (at most CHORD); a face's loops
    are built on its first test."""

    def __init__(self, model: CadModel, tolerance: float) -> None:
        self.model, self.tolerance = model, min(tolerance, CHORD)
        self.topo = Topology.of(model.shape)
        self._loops: dict[int, tuple[list[np.ndarray], np.ndarray] | None] = {}

    def loops(self, face: int) -> tuple[list[np.ndarray], np.ndarray] | None:
        """The face's wires as (n, 2) polygons in (u,v) and their (u,v) box's middle (2,); None where a wire cannot
        be walked."""
        if face not in self._loops:
            try:
                found = [lp["uv"] for lp in boundary_loops(self.model.faces[face], self.topo, self.tolerance,
                                                           MeshParams.angular)]
            except AmprepError:
                found = []
            found = [lp for lp in found if len(lp) >= 3]
            every = np.concatenate(found) if found else None
            self._loops[face] = None if every is None else (found, (every.min(axis=0) + every.max(axis=0)) / 2)
        return self._loops[face]

    def inside(self, face: int, uv: np.ndarray, periods: tuple[float | None, float | None]) -> np.ndarray:
        """(k,) bool: the points uv (k, 2) inside the face's trimmed domain (even-odd over its loops), each periodic
        parameter first moved by whole periods next to the loops' middle; all True where the loops are unknown."""
        known = self.loops(face)
        if known is None:
            return np.ones(len(uv), bool)
        loops, middle = known
        pts = np.asarray(uv, float)
        return inside_loops(nearest_copy(pts, np.broadcast_to(middle, pts.shape), periods), loops)
