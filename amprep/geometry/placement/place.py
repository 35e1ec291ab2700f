"""A user's STL put on its CAD: aligned (axis permutations, ICP, a fit to the exact surfaces), each triangle given
its CAD face and each corner its (u,v)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.bspline import COMPILED_MIN_POINTS
from amprep.geometry.cad.read import CadModel
from amprep.geometry.cad.surfaces import Surface, surface_of
from amprep.geometry.core.compiled import compiled
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import Progress
from amprep.geometry.measure import cusp
from amprep.geometry.measure.report import Issue
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model

#: Gauss–Newton rounds of the fit to the exact surfaces (align.point_to_plane), each after a new projection
POLISH_ROUNDS = 8
#: a corner within this × the diagonal (or 8 float32 steps of its largest coordinate) of a face's surface lies on it
SNAP = 1e-6
#: the polish stops at a round that moves no corner by more than this × the diagonal (later rounds on CTC-02's
#: B-spline twin moved them by 1e-10 mm, each at 7 s)
SETTLED = 1e-9
#: corners farther from their face than this × the 90th percentile of that face's corners' distances are left out of
#: a round
TRIM = 3.0
#: a part with this many free-form faces is placed with the compiled evaluator, whatever the STL's size
FREE_FORM_FACES = 60


@dataclass(frozen=True, eq=False)
class PlacedStl:
    """A user's STL put on its CAD: `mesh` in the CAD's frame with face ids and (u,v) by projection (face −1:
    unmatched), `fit` the rigid motion (user → CAD), `tolerance` the match tolerance, `surfaces` per face id."""

    mesh: Mesh
    fit: Any
    tolerance: float
    surfaces: dict[int, Surface]
    reference_faces: tuple

    @property
    def unmatched(self) -> int:
        return int((self.mesh.face_ids < 0).sum())

    def alignment(self) -> dict[str, Any]:
        return self.fit.as_dict() | {"match_tolerance": self.tolerance, "unmatched_triangles": self.unmatched}


def place_user_stl(model: CadModel, user: Mesh, mesh_params: MeshParams, prog: Progress | None = None) -> PlacedStl:
    """Align an STL made elsewhere on its CAD (axis permutations, then ICP, then a fit to the exact surfaces) and
    give each triangle its face and (u,v) by projection, each apex or pole corner given the middle of its triangle's
    other corners in its free parameter (project.with_free_corners_centred); stl_mismatch when it does not fit."""
    from dataclasses import replace

    from amprep.geometry.placement.align import align
    from amprep.geometry.placement.project import ReferenceCloud

    prog = prog or Progress(None)
    diag = float(np.linalg.norm(np.ptp(user.vertices, axis=0)))
    if not diag > 0 or not np.isfinite(diag) or not cusp.unit_normals(user.corners)[1].sum() > 0:
        raise AmprepError(ErrorCode.STL_MISMATCH, "the STL has no area to place on its CAD (every triangle is a point "
                          "or a line)")
    prog("reference tessellation", 0.0)
    ref_tol = min(mesh_params.tolerance, max(diag * 2e-4, 1e-3))
    reference = mesh_model(model, replace(mesh_params, tolerance=ref_tol, relative=None), prog.span(0.0, 0.6))
    spacing = max(diag / 400, 0.01)
    error = reference.max_error  # nan when no face has a surface: then no point is ruled out by its distance
    cloud = ReferenceCloud.of(reference.mesh, spacing, error=max(error, ref_tol) if np.isfinite(error) else np.inf)
    prog("aligning the STL on the CAD", 0.6)
    tol = max(1e-3 * diag, 0.02)
    even, _, _ = cusp.point_cloud(user.corners, 1.0, max_points=50_000)
    cad_even, _, _ = cusp.point_cloud(reference.mesh.corners, 1.0, max_points=50_000)
    fit = align(user.vertices, cloud.points, inlier_distance=tol + spacing, stl_cloud=even, cad_cloud=cad_even,
                tree=cloud.tree)
    surfaces = {i: surface_of(f) for i, f in enumerate(model.faces)}
    prog("isolating faces", 0.8)
    # each round projects every corner on its candidate faces, a few points per call: by the compiled kernels where
    # _worth_compiling says (decided by the input, not by what is loaded)
    with compiled(_worth_compiling(user, surfaces)):
        scored, fit = _polished(user, fit, cloud, surfaces, reference.mesh.faces, tol, spacing, diag,
                                prog.span(0.8, 1.0))
    prog("placed", 1.0)
    return PlacedStl(scored, fit, tol, surfaces, reference.mesh.faces)


def _worth_compiling(user: Mesh, surfaces: dict[int, Surface]) -> bool:
    """True when placing `user` projects onto faces often enough to pay numba's start-up (the compiled evaluator, and
    the projection's loop in one call per face, _projection_kernel.py): every corner of the STL projected
    POLISH_ROUNDS + 1 times is COMPILED_MIN_POINTS, or the part has FREE_FORM_FACES B-spline or Bézier faces (each
    projected in its own calls, a few Newton steps each, every one a numpy call of ~0.1 ms however few its points:
    as1's 70 B-spline faces, its 2,308-triangle STL, 4.7 → 3.1 s with the start-up; 45 faces break even)."""
    free_form = sum(s.surface_type in ("bspline", "bezier") and s.data is not None for s in surfaces.values())
    compiled_kinds = free_form + sum(s.closed_form is not None for s in surfaces.values())
    return compiled_kinds > 0 and (3 * user.n_triangles * (POLISH_ROUNDS + 1) >= COMPILED_MIN_POINTS
                                   or free_form >= FREE_FORM_FACES)


def _polished(user: Mesh, fit: Any, cloud: Any, surfaces: dict[int, Surface], faces: tuple, tol: float,
              spacing: float, diag: float, prog: Progress) -> tuple[Mesh, Any]:
    """(the STL placed: each triangle its face within `tol`, (u,v), free corners centred; the fit polished against
    the exact surfaces): corners matched within the coarse fit's reach pulled onto their faces' tangent planes, round
    by round, until a round moves none by more than SETTLED × the diagonal; `prog` told of each round."""
    from dataclasses import replace

    from amprep.geometry.cad.surfaces import surface_normals
    from amprep.geometry.placement.align import point_to_plane
    from amprep.geometry.placement.project import RESTARTS, isolate, with_free_corners_centred

    # the polish matches within the coarse fit's reach too: ICP on area samples of a coarse STL sits its facets, not
    # its corners, on the surface (a 0.5 mm STL of a 12 mm cone: 0.07 mm off, no corner within tol)
    reach = tol + spacing + 3 * fit.rms
    snap = max(SNAP * diag, 8 * float(np.spacing(np.float32(np.abs(user.vertices).max()))))
    for step in range(POLISH_ROUNDS):  # polish the fit against the exact surfaces: matched corners onto their planes
        prog("isolating faces", step / (POLISH_ROUNDS + 1))
        placed = Mesh.from_arrays(fit.apply(user.vertices), user.triangles)
        scored, dist = isolate(placed, cloud, surfaces, faces, reach, snap)
        ok = scored.face_ids >= 0
        if ok.sum() < 3:
            break
        groups = [np.flatnonzero(scored.face_ids == f) for f in np.unique(scored.face_ids[ok])]
        uvs = [(surfaces[int(scored.face_ids[g[0]])], scored.uv[g].reshape(-1, 2)) for g in groups]
        tgt = np.concatenate([sf.evaluate(uv) for sf, uv in uvs])
        normals = np.concatenate([surface_normals(sf, uv) for sf, uv in uvs])
        tris = np.concatenate(groups)
        src = placed.corners[tris].reshape(-1, 3)
        _, area = cusp.unit_normals(placed.corners[tris])
        off = dist[tris].ravel()  # corners far off their face (a triangle given a neighbour's face) do not pull the fit
        # judged against the corners of the same face: a face the coarse fit left off as a whole (a bar's end, the
        # only face that holds it along its axis) is the fit's error, not an outlier
        typical = np.concatenate([np.full(3 * len(g), float(np.quantile(dist[g], 0.9))) for g in groups])
        near = off <= np.maximum(TRIM * typical, 1e-6 * diag)
        if near.sum() < 3:
            break
        dR, dt = point_to_plane(src[near], tgt[near], normals[near],  # weighted by area, like the surface
                                np.repeat(area, 3)[near] + 1e-12)
        fit = replace(fit, rotation=dR @ fit.rotation, translation=dR @ fit.translation + dt)
        turn = 3 * np.abs(dR - np.eye(3)).max() * float(np.abs(placed.vertices).max())  # bounds |(dR − I)·x|
        if turn + np.linalg.norm(dt) <= SETTLED * diag:
            break  # no corner moved by more than that: the rounds after it move them by rounding noise
    prog("isolating faces", POLISH_ROUNDS / (POLISH_ROUNDS + 1))
    placed = Mesh.from_arrays(fit.apply(user.vertices), user.triangles)
    scored, dist = isolate(placed, cloud, surfaces, faces, tol, snap, restarts=RESTARTS)
    # a pole's free parameter, wherever its projection left it, would fold its triangles' (u,v)
    scored = with_free_corners_centred(scored, surfaces, snap)
    d_ok = dist[scored.face_ids >= 0]
    fit = replace(fit, rms=float(np.sqrt(np.mean(d_ok**2))) if d_ok.size else fit.rms,
                  max=float(d_ok.max()) if d_ok.size else fit.max)
    return scored, fit


def unmatched_issue(placed: PlacedStl) -> Issue:
    """The issue for STL triangles that match no CAD face."""
    return Issue("unmatched_triangles", "warning", placed.unmatched, f"STL triangles with a corner farther than "
                 f"{placed.tolerance:.3g} mm from every CAD face: the STL differs from the CAD there (not scored)")
