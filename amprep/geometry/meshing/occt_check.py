"""The first look at OCCT's mesh of every face: its triangulation read with its edge keys, checked (a boundary that
is the B-rep's, no flat triangle) and its chordal error measured, for a chunk of faces at a time with the numpy work
done on the chunk's triangles at once (a face at 0.1 mm has tens of triangles: per-face calls would cost more than
the arithmetic), the chunks shared by this process and forked workers (face_pool.py)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from OCP.TopoDS import TopoDS_Face

from amprep.geometry.cad.surfaces import Surface, plane
from amprep.geometry.cad.topology import Topology
from amprep.geometry.measure.chordal import affine_chordal_bound, kernels_loaded, triangle_chordal_error
from amprep.geometry.meshing.local_refine import flat_triangles
from amprep.geometry.meshing.occt_read import FacePatch, PatchRead, off_boundary_edges, read_patch
from amprep.geometry.parallel.face_pool import map_faces

#: faces per chunk
CHUNK_FACES = 32
#: a face's first look costs about this many re-meshed triangles' time (face_pool's unit), plus PER_TRIANGLE for each
#: of its triangles
PER_FACE = 40
PER_TRIANGLE = 0.15


@dataclass
class Look:
    """One face after the first look: what read_patch found, why it must be meshed again (None: OCCT's mesh is
    kept), and the chordal error (t,) of OCCT's triangles when kept."""

    found: PatchRead
    reason: str | None
    error: np.ndarray | None

    @property
    def patch(self) -> FacePatch | None:
        """OCCT's patch when it is kept and assembled in this process (found.assemble makes it in another)."""
        return self.found.patch if self.reason is None else None


def patch_error(patch: FacePatch, surface: Surface | None, order: int) -> np.ndarray:
    """(t,) chordal error of each triangle of a patch (nan when the face has no surface or no (u,v))."""
    if surface is None or patch.uv is None or patch.meshed_by == "stored":
        return np.full(len(patch.tris), np.nan)
    if patch.error is not None:  # the fallback mesher measured its own triangles
        return patch.error
    return triangle_chordal_error(patch.nodes[patch.tris], patch.uv[patch.tris], surface, order,
                                  affine=surface.affine)


def stack_patches(patches: Sequence[FacePatch]) -> tuple[FacePatch, np.ndarray, np.ndarray]:
    """(one FacePatch holding all the patches' nodes and triangles (the node keys kept, the (u,v) when every patch has
    them), (T,) the index in `patches` of each triangle, (K + 1,) node offsets)."""
    offsets = np.cumsum([0] + [len(p.nodes) for p in patches])
    tris = np.concatenate([p.tris + o for p, o in zip(patches, offsets, strict=False)])
    owner = np.repeat(np.arange(len(patches)), [len(p.tris) for p in patches])
    uv = np.concatenate([p.uv for p in patches]) if all(p.uv is not None for p in patches) else None
    stacked = FacePatch(-1, np.concatenate([p.nodes for p in patches]), uv, tris,
                        np.concatenate([p.node_vertex for p in patches]),
                        np.concatenate([p.node_edge for p in patches]),
                        np.concatenate([p.node_param for p in patches]))
    return stacked, owner, offsets


def _plane_errors(patches: Sequence[FacePatch], surfaces: Sequence[Surface]) -> list[np.ndarray]:
    """patch_error of patches on planes, for all of them at once: chordal.affine_chordal_bound of every triangle,
    each corner evaluated on its own face's plane (surfaces.plane with per-corner frames)."""
    stacked, owner, _ = stack_patches(patches)
    frames = np.array([s.closed_form[1][:9] for s in surfaces])[np.repeat(owner, 3)]  # type: ignore[index]
    t = stacked.tris
    err = affine_chordal_bound(stacked.nodes[t], stacked.uv[t],  # type: ignore[index]
                               plane(frames[:, 0:3], frames[:, 3:6], frames[:, 6:9]))
    return np.split(err, np.cumsum([len(p.tris) for p in patches])[:-1])


def rejected(patches: Sequence[FacePatch], min_area: float,
             segments: Sequence[np.ndarray] | None = None) -> list[str | None]:
    """Why each of OCCT's patches cannot be kept, checked on all their triangles at once: "broken_triangulation"
    (check_patch_boundary fails, given each patch's edge polygon `segments` (s, 2) when known), "degenerate_triangles"
    (flat_triangles finds one), or None."""
    stacked, owner, offsets = stack_patches(patches)
    joined = (np.concatenate([s + o for s, o in zip(segments, offsets, strict=False)]) if segments is not None
              else None)
    broken = np.zeros(len(patches), bool)
    broken[np.searchsorted(offsets, off_boundary_edges(stacked, joined)[:, 0], side="right") - 1] = True
    flat = np.bincount(owner, flat_triangles(stacked, min_area), minlength=len(patches)) > 0
    return ["broken_triangulation" if b else "degenerate_triangles" if f else None for b, f in zip(broken, flat, strict=True)]


def _look_at(faces: Sequence[TopoDS_Face], ids: range, topo: Topology, bulk: Sequence, surfaces: Sequence[Surface | None],  # type: ignore[type-arg]
             skip: dict[int, str], order: int, min_area: float) -> _Chunk:
    """The Looks of the faces `ids`."""
    looks = {}
    for i in ids:
        if i in skip:
            looks[i] = Look(PatchRead(i), skip[i], None)
            continue
        found = read_patch(i, faces[i], topo, bulk[i])
        looks[i] = Look(found, None if found.patch is not None else "no_triangulation", None)
    occt = [i for i in ids if looks[i].patch is not None and not looks[i].found.stored]
    if occt:
        reasons = rejected([looks[i].found.patch for i in occt], min_area,  # type: ignore[misc]
                           [looks[i].found.segments for i in occt])
        for i, reason in zip(occt, reasons, strict=True):
            looks[i].reason = reason
    kept = [i for i in ids if looks[i].patch is not None]
    planes = [i for i in kept if _on_plane(looks[i].patch, surfaces[i])]  # type: ignore[arg-type]
    if planes:
        for i, err in zip(planes, _plane_errors([looks[i].patch for i in planes], [surfaces[i] for i in planes]),  # type: ignore[misc]
                          strict=True):
            looks[i].error = err
    for i in kept:
        if looks[i].error is None:
            looks[i].error = patch_error(looks[i].patch, surfaces[i], order)  # type: ignore[arg-type]
    return _Chunk([looks[i] for i in ids])


class _Chunk:
    """A chunk's Looks, sent between processes as eleven flat arrays (pickling thousands of small arrays one by one
    cost more than the arrays: 0.1-0.3 s for 4,806 faces)."""

    def __init__(self, looks: list[Look]) -> None:
        self.looks = looks

    def __getstate__(self) -> dict:  # type: ignore[type-arg]
        looks = self.looks
        keyed = [lk.found.keys for lk in looks if lk.found.keys is not None]
        errors = [lk.error for lk in looks if lk.error is not None]

        def cat(parts: list[np.ndarray], dtype: type) -> np.ndarray:
            return np.concatenate(parts) if parts else np.zeros(0, dtype)

        meta = [(lk.found.face_id, lk.reason, lk.found.stored, lk.found.keys is not None,
                 len(lk.found.keys[0]) if lk.found.keys is not None else 0, len(lk.found.edges),
                 len(lk.error) if lk.error is not None else -1, lk.found.merges) for lk in looks]
        arrays = [cat([k[j] for k in keyed], t) for j, t in enumerate((np.int64, np.int64, np.int64, float))]
        arrays += [cat([lk.found.edges for lk in looks], np.int64), cat([lk.found.sizes for lk in looks], np.int64),
                   cat([lk.found.params for lk in looks], float), cat(errors, float)]
        return {"meta": meta, "arrays": arrays}

    def __setstate__(self, state: dict) -> None:  # type: ignore[type-arg]
        ids, vertex, edge, param, edges, sizes, params, errors = state["arrays"]
        at = dict.fromkeys(("key", "edge", "param", "error"), 0)
        self.looks = []
        for face_id, reason, stored, has_keys, n_keys, n_edges, n_error, merges in state["meta"]:
            k, e, p = at["key"], at["edge"], at["param"]
            n_params = int(sizes[e:e + n_edges].sum())
            found = PatchRead(face_id, (ids[k:k + n_keys], vertex[k:k + n_keys], edge[k:k + n_keys],
                                        param[k:k + n_keys]) if has_keys else None,
                              edges[e:e + n_edges], sizes[e:e + n_edges], params[p:p + n_params], merges, stored)
            error = errors[at["error"]:at["error"] + n_error] if n_error >= 0 else None
            self.looks.append(Look(found, reason, error))
            at["key"] += n_keys
            at["edge"] += n_edges
            at["param"] += n_params
            at["error"] += max(n_error, 0)


def _on_plane(patch: FacePatch, surface: Surface | None) -> bool:
    return surface is not None and surface.affine and surface.closed_form is not None and patch.uv is not None


def first_look(faces: Sequence[TopoDS_Face], topo: Topology, bulk: Sequence, surfaces: Sequence[Surface | None],  # type: ignore[type-arg]
               skip: dict[int, str], order: int, min_area: float) -> list[Look]:
    """The Look of every face (`skip`: faces not to read, and why), in chunks of CHUNK_FACES, in parallel once the
    compiled kernels run every chordal measure (then every process computes the same numbers); `topo` is left
    unchanged (PatchRead.record adds what was found)."""
    n = len(faces)
    chunks = [range(s, min(n, s + CHUNK_FACES)) for s in range(0, n, CHUNK_FACES)]
    cost = [sum(PER_FACE + PER_TRIANGLE * (len(bulk[i][2]) if bulk[i] is not None else 0) for i in c) for c in chunks]
    order_ = sorted(range(len(chunks)), key=lambda k: (-cost[k], k))
    done = map_faces(lambda k: _look_at(faces, chunks[k], topo, bulk, surfaces, skip, order, min_area), order_,
                     ready=kernels_loaded, cost=[cost[k] for k in order_])
    return [look for k in range(len(chunks)) for look in done[k].looks]
