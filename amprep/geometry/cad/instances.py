"""One part placed many times is meshed once: an assembly whose solids are instances of fewer distinct solids (one
TShape under several locations) is meshed as those distinct solids, unplaced, and each instance is that mesh moved
by its location (a mirroring one reverses its triangles). 65,536 placed boxes cost what one box and a matrix
product cost; the output is the one the whole assembly would mesh to, face ids, solids and B-rep keys included.

Used when every face lies in a solid, no two solids share a face, edge or vertex (each instance is closed on its
own), and the distinct solids hold at most half the faces; otherwise the whole model is meshed as it is."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SOLID, TopAbs_VERTEX
from OCP.TopExp import TopExp
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from amprep.geometry.cad.read import CadModel, model_from_shape
from amprep.geometry.cad.topology import compound, explore, trsf_matrix
from amprep.geometry.core.mesh import IN_FACE, ON_BREP_EDGE, ON_BREP_VERTEX, FaceInfo, Mesh

_KINDS = (TopAbs_FACE, TopAbs_EDGE, TopAbs_VERTEX)


def _counts(shape: TopoDS_Shape) -> tuple[int, int, int]:
    """(faces, edges, vertices) of a shape, each counted once."""
    out = []
    for kind in _KINDS:
        m = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(shape, kind, m)
        out.append(m.Extent())
    return out[0], out[1], out[2]


@dataclass(frozen=True, eq=False)
class Instancing:
    """A model's solids as placements of distinct parts: `template` the distinct solids unplaced (a CadModel),
    `part_of` (k,) the part of each solid of the model (in its order), `placement` (k, 3, 4) each solid's location,
    `counts` (p, 3) faces, edges, vertices of each part; a part's items come as one run in the template and each
    solid's as one run in the model (`start` (k, 3) where), in the same order."""

    template: CadModel
    part_of: np.ndarray
    placement: np.ndarray
    counts: np.ndarray
    start: np.ndarray

    @property
    def part_start(self) -> np.ndarray:
        """(p, 3) where each part's faces, edges and vertices start in the template."""
        return np.vstack([np.zeros((1, 3), np.int64), np.cumsum(self.counts, axis=0)[:-1]])


def find_instancing(model: CadModel) -> Instancing | None:
    """The model's Instancing when it pays and holds (the module's docstring), else None."""
    solids = explore(model.shape, TopAbs_SOLID, TopoDS.Solid_s)
    if len(solids) < 2 or min(model.face_solid, default=-1) < 0:
        return None
    parts: list[TopoDS_Shape] = []
    known: dict[int, list[int]] = {}
    part_of = np.zeros(len(solids), np.int64)
    for k, solid in enumerate(solids):
        bare = solid.Located(TopLoc_Location())
        same = known.setdefault(hash(bare), [])
        p = next((p for p in same if parts[p].IsEqual(bare)), None)
        if p is None:
            p = len(parts)
            parts.append(bare)
            same.append(p)
        part_of[k] = p
    counts = np.array([_counts(p) for p in parts], np.int64)
    if 2 * counts[:, 0].sum() > len(model.faces):
        return None
    template = model_from_shape(compound(parts), model.format, model.units, model.sewn, model.notes, model.unsupported)
    per_solid = counts[part_of]
    start = np.vstack([np.zeros((1, 3), np.int64), np.cumsum(per_solid, axis=0)[:-1]])
    full = _counts(model.shape)
    if tuple(per_solid.sum(axis=0)) != full or tuple(counts.sum(axis=0)) != _counts(template.shape):
        return None  # some solids share faces, edges or vertices
    placement = np.array([_matrix(s) for s in solids])
    inst = Instancing(template, part_of, placement, counts, start)
    return inst if _runs_hold(inst, model, solids, parts) else None


def _matrix(shape: TopoDS_Shape) -> np.ndarray:
    m = trsf_matrix(shape.Location())
    return np.hstack([np.eye(3), np.zeros((3, 1))]) if m is None else m


def _runs_hold(inst: Instancing, model: CadModel, solids: list, parts: list) -> bool:  # type: ignore[type-arg]
    """True when the first and last face of the first, middle and last solid sit where the runs say, in the model
    and in the template (a check of the layout the expansion relies on)."""
    first = inst.part_start
    for k in sorted({0, len(solids) // 2, len(solids) - 1}):
        p = int(inst.part_of[k])
        mine = explore(solids[k], TopAbs_FACE, TopoDS.Face_s)
        bare = explore(parts[p], TopAbs_FACE, TopoDS.Face_s)
        for j in (0, int(inst.counts[p, 0]) - 1):
            if not (model.faces[int(inst.start[k, 0]) + j].IsEqual(mine[j])
                    and inst.template.faces[int(first[p, 0]) + j].IsEqual(bare[j])):
                return False
    return True


def expand_mesh(inst: Instancing, mesh: Mesh, faces: tuple[FaceInfo, ...]) -> Mesh:
    """The template's mesh placed once per solid, in the model's solid order: vertices moved by each placement,
    triangles reversed under a mirroring one, face ids and B-rep keys moved to the solid's own runs; `faces` the
    model's FaceInfo."""
    first = inst.part_start
    vert_blocks, tri_blocks, fid_blocks, uv_blocks, dim_blocks, ent_blocks, par_blocks, owner_t, owner_v = ([] for _ in range(9))
    base = 0
    for p in range(len(inst.counts)):
        lo, hi = first[p, 0], first[p, 0] + inst.counts[p, 0]
        sel = np.flatnonzero((mesh.face_ids >= lo) & (mesh.face_ids < hi))
        used, local = np.unique(mesh.triangles[sel], return_inverse=True)
        local = local.reshape(-1, 3)
        ks = np.flatnonzero(inst.part_of == p)
        if len(ks) == 0:
            continue
        m = inst.placement[ks]  # (K, 3, 4)
        v = np.einsum("kij,nj->kni", m[:, :, :3], mesh.vertices[used]) + m[:, None, :, 3]
        mirrored = np.linalg.det(m[:, :, :3]) < 0
        offsets = base + np.arange(len(ks)) * len(used)
        tris = local[None] + offsets[:, None, None]
        tris = np.where(mirrored[:, None, None], tris[:, :, [0, 2, 1]], tris)
        vert_blocks.append(v.reshape(-1, 3))
        tri_blocks.append(tris.reshape(-1, 3))
        fid_blocks.append((mesh.face_ids[sel][None] - lo + inst.start[ks, 0][:, None]).reshape(-1))
        if mesh.uv is not None:
            uv = np.broadcast_to(mesh.uv[sel], (len(ks), *mesh.uv[sel].shape))
            uv_blocks.append(np.where(mirrored[:, None, None, None], uv[:, :, [0, 2, 1]], uv).reshape(-1, 3, 2))
        if mesh.vertex_dim is not None and mesh.vertex_entity is not None and mesh.vertex_param is not None:
            dim, ent = mesh.vertex_dim[used], mesh.vertex_entity[used].astype(np.int64)
            shift = np.zeros((len(ks), len(used)), np.int64)
            for d, col in ((ON_BREP_VERTEX, 2), (ON_BREP_EDGE, 1), (IN_FACE, 0)):
                on = dim == d
                shift[:, on] = inst.start[ks, col][:, None] - first[p, col]
            dim_blocks.append(np.tile(dim, len(ks)))
            ent_blocks.append((ent[None] + shift).reshape(-1))
            par_blocks.append(np.tile(mesh.vertex_param[used], len(ks)))
        owner_t.append(np.repeat(ks, len(sel)))
        owner_v.append(np.repeat(ks, len(used)))
        base += len(ks) * len(used)
    t_order = np.argsort(np.concatenate(owner_t), kind="stable")
    v_order = np.argsort(np.concatenate(owner_v), kind="stable")
    new_index = np.empty_like(v_order)
    new_index[v_order] = np.arange(len(v_order))
    pick = (lambda blocks, order: np.concatenate(blocks)[order] if blocks else None)  # noqa: E731
    ent = pick(ent_blocks, v_order)
    return Mesh(np.concatenate(vert_blocks)[v_order], new_index[np.concatenate(tri_blocks)[t_order]],
                np.concatenate(fid_blocks)[t_order].astype(np.int32), pick(uv_blocks, t_order),
                pick(dim_blocks, v_order), None if ent is None else ent.astype(np.int32),
                pick(par_blocks, v_order), faces)


def template_face_of(inst: Instancing) -> np.ndarray:
    """(F,) the template face behind each face of the model."""
    first = inst.part_start
    n = inst.counts[inst.part_of, 0]
    return np.repeat(first[inst.part_of, 0] - inst.start[:, 0], n) + np.arange(int(n.sum()))
