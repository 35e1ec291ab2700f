"""gmsh (Frontal-Delaunay) sized to a chord tolerance, as a peer for the regularity tables: an equally regular mesher.

gmsh has no chord tolerance. Its size here comes from a callback: on a face √(8 · 0.95 ε / κ) with κ the larger
principal curvature there (the sagitta of a chord of that length on a circle of radius 1/κ is 0.95 ε, the quality
mesher's own lattice SAFETY); on an edge the least of that over the faces it bounds and of its own curvature's
size; no limit where nothing is curved (sizes then grow from the boundary, gmsh's default). The same isotropic
rule the quality mesher's (u,v) cells follow, so its counts compare with ours; its chordal error is then measured
with amprep's own measure in each triangle's (u,v) on the B-rep face gmsh meshed (gmsh numbers the faces in its own
order: each is matched to amprep's by bounding box and by its (u,v) giving back gmsh's points, else by its corners'
projections lying on the surface, whose (u,v) are then used; one that matches none is left unmeasured).
"""

from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepBndLib import BRepBndLib
from OCP.gp import gp_Pnt
from OCP.ShapeAnalysis import ShapeAnalysis_Surface

from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import Surface, surface_of
from amprep.geometry.core.mesh import FaceInfo, Mesh
from amprep.geometry.measure.chordal import triangle_chordal_error
from amprep.geometry.meshing.lattice import SAFETY
from amprep.geometry.placement.project import unwrap_corners


def _size_callback(gmsh, tol: float):  # type: ignore[no-untyped-def]
    """gmsh's size callback (dim, tag, x, y, z, lc) → size for the chord tolerance `tol` (mm)."""
    up = {c: list(gmsh.model.getAdjacencies(1, c)[0]) for _, c in gmsh.model.getEntities(1)}

    def kmax(s: int, xyz: list[float]) -> float:
        uv = gmsh.model.getParametrization(2, s, xyz)
        k1, k2, _, _ = gmsh.model.getPrincipalCurvatures(s, uv)
        return max(abs(k1[0]), abs(k2[0]))

    def size(dim: int, tag: int, x: float, y: float, z: float, lc: float) -> float:
        xyz = [x, y, z]
        try:
            if dim == 2:
                k = kmax(tag, xyz)
            elif dim == 1:
                t = gmsh.model.getParametrization(1, tag, xyz)
                k = max([kmax(s, xyz) for s in up.get(tag, [])] + [abs(gmsh.model.getCurvature(1, tag, t)[0])])
            else:
                return lc
        except Exception:  # a point gmsh cannot parametrise: its own size
            return lc
        return min(lc, math.sqrt(8 * SAFETY * tol / k)) if 1e-12 < k < math.inf else lc

    return size


def mesh_gmsh(path: Path, tol: float, model: CadModel, faces: tuple[FaceInfo, ...],
              timeout: float = 900.0) -> dict | None:  # type: ignore[type-arg]
    """{'mesh': Mesh (face ids as amprep's), 'seconds' (gmsh's import and meshing, the Python size callback
    included), 'max_error' (mm, over the measured faces), 'over' (triangles over `tol`), 'unmeasured' (faces)}; gmsh
    runs in a child process, None when it fails or takes over `timeout` seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "gmsh.npz"
        try:
            subprocess.run([sys.executable, __file__, str(path), str(tol), str(out)], check=True, timeout=timeout,
                           capture_output=True)
        except (subprocess.CalledProcessError, subprocess.TimeoutExpired):
            return None
        d = dict(np.load(out))
    coord, tri, face_ids, uv = d["coord"], d["tri"], d["face"], d["uv"]
    scale = float(np.ptp(coord, axis=0).max())
    surfaces: dict[int, Surface] = {}
    face_ids = _our_faces(face_ids, d["boxes"], coord, tri, uv, model, surfaces, 1e-6 * scale + 1e-6)
    max_error, over = 0.0, 0
    for f in np.unique(face_ids[face_ids >= 0]):
        sel = face_ids == f
        surface = surfaces[int(f)]
        e = triangle_chordal_error(coord[tri[sel]], unwrap_corners(uv[sel], surface.periods), surface,
                                   affine=surface.affine)
        max_error, over = max(max_error, float(e.max())), over + int((e > tol).sum())
    unmeasured = len(np.unique(d["face"][face_ids < 0]))
    mesh = Mesh(coord, tri, face_ids.astype(np.int32), faces=faces)
    return {"mesh": mesh, "seconds": float(d["seconds"]), "max_error": max_error, "over": over,
            "unmeasured": unmeasured}


def _our_faces(gmsh_face: np.ndarray, boxes: np.ndarray, coord: np.ndarray, tri: np.ndarray, uv: np.ndarray,
               model: CadModel, surfaces: dict[int, Surface], close: float) -> np.ndarray:
    """(t,) amprep's face id of each of gmsh's triangles (−1: none found): gmsh may number the faces in its own order
    (CTC-02's), so each of its faces is tried on ours of the same number first, then on ours whose bounding box is
    within 1 % of the part's size of its own (boxes (F, 6)): the first whose surface, at gmsh's (u,v) of the face's
    corners, gives back gmsh's points (to `close`), else the first its corners project onto. Each surface is read
    once, into `surfaces`."""
    ours = []
    for face in model.faces:
        box = Bnd_Box()
        BRepBndLib.Add_s(face, box)
        ours.append(box.Get())
    ours_box = np.array(ours)
    reach = 0.01 * float(np.ptp(coord, axis=0).max())
    out = np.full(len(gmsh_face), -1, np.int64)
    for g in np.unique(gmsh_face):
        sel = np.flatnonzero(gmsh_face == g)
        pts, guv = coord[tri[sel]].reshape(-1, 3), uv[sel]
        near = np.flatnonzero(np.abs(ours_box - boxes[g]).max(axis=1) <= reach)
        candidates = np.concatenate([[g] if g < len(model.faces) else [], near[near != g]]).astype(np.int64)
        for f in candidates:
            if int(f) not in surfaces:
                surfaces[int(f)] = surface_of(model.faces[f])
            surface = surfaces[int(f)]
            fuv = unwrap_corners(guv, surface.periods).reshape(-1, 2)
            if np.abs(surface.evaluate(fuv) - pts).max() <= close:
                out[sel] = f
                break
        else:  # gmsh's (u,v) is not ours on any: the corners projected on each candidate's surface instead
            for f in candidates:
                projected = _projected(model.faces[f], pts, close)
                if projected is not None:
                    out[sel], uv[sel] = f, projected.reshape(-1, 3, 2)
                    break
    return out


def _projected(face, pts: np.ndarray, close: float) -> np.ndarray | None:  # type: ignore[no-untyped-def]
    """(n, 2) the (u,v) of points (n, 3) on the face's surface, None when one lies farther than 1000 × `close`."""
    surface = ShapeAnalysis_Surface(BRep_Tool.Surface_s(face))
    out = np.empty((len(pts), 2))
    for i, p in enumerate(pts):
        q = gp_Pnt(*p)
        uv = surface.ValueOfUV(q, close)
        if surface.Gap() > 1000 * close:
            return None
        out[i] = uv.X(), uv.Y()
    return out


def _run(path: Path, tol: float, out: Path) -> None:
    """In the child: gmsh's mesh of `path` at `tol`, saved to `out` (coord, tri, face (its faces in order), uv,
    boxes (its faces' bounding boxes), seconds)."""
    import gmsh

    t0 = time.perf_counter()
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        if path.suffix.lower() in (".stp", ".step"):
            gmsh.option.setString("Geometry.OCCTargetUnit", "MM")
        gmsh.model.occ.importShapes(str(path))
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.setSizeCallback(_size_callback(gmsh, tol))
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.model.mesh.generate(2)
        seconds = time.perf_counter() - t0
        tags, coord, _ = gmsh.model.mesh.getNodes()
        coord = np.asarray(coord).reshape(-1, 3)
        where = np.zeros(int(np.max(tags)) + 1, np.int64)
        where[np.asarray(tags, np.int64)] = np.arange(len(tags))
        tris, ids, uvs, boxes = [], [], [], []  # type: ignore[var-annotated]
        for _, s in gmsh.model.getEntities(2):
            types, _, nodes = gmsh.model.mesh.getElements(2, s)
            if 2 not in list(types):
                continue
            t = where[np.asarray(nodes[list(types).index(2)], np.int64).reshape(-1, 3)]
            tris.append(t)
            ids.append(np.full(len(t), len(boxes), np.int32))
            boxes.append(gmsh.model.getBoundingBox(2, s))
            uvs.append(np.asarray(gmsh.model.getParametrization(2, s, coord[t].ravel())).reshape(-1, 3, 2))
    finally:
        gmsh.finalize()
    np.savez(out, coord=coord, tri=np.concatenate(tris), face=np.concatenate(ids), uv=np.concatenate(uvs),
             boxes=np.array(boxes), seconds=seconds)


if __name__ == "__main__":
    _run(Path(sys.argv[1]), float(sys.argv[2]), Path(sys.argv[3]))
