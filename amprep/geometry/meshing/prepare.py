"""A model made ready for meshing: its absolute tolerance worked out once, the faces we mesh ourselves from the
start chosen once, and every other face meshed by BRepMesh at that tolerance (brepmesh.py)."""

from __future__ import annotations

from dataclasses import dataclass

from amprep.geometry.cad.read import CadModel
from amprep.geometry.meshing.brepmesh import run_brepmesh
from amprep.geometry.meshing.large_faces import faces_to_mesh_ourselves
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.tolerance import absolute_tolerance


@dataclass(frozen=True, eq=False)
class Prepared:
    """A model whose shape BRepMesh meshed at `tolerance` (mm, absolute), all faces but `own` (ids left to our own
    mesher, large_faces.py)."""

    model: CadModel
    tolerance: float
    own: tuple[int, ...]


def own_faces(model: CadModel, params: MeshParams, tol: float) -> list[int]:
    """Ids of the faces meshed by us from the start (large_faces.py), none when not own_large_faces."""
    if not params.own_large_faces or params.force_fallback:
        return []
    return faces_to_mesh_ourselves(model.faces, tol)


def prepare(model: CadModel, params: MeshParams) -> Prepared:
    """The model's absolute tolerance and own faces, after run_brepmesh meshed every other face at that tolerance."""
    tol = absolute_tolerance(model, params)
    own = own_faces(model, params, tol)
    run_brepmesh(model.shape, tol, params, [model.faces[i] for i in own])
    return Prepared(model, tol, tuple(own))
