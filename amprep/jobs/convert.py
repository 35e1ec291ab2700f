"""The convert job: read any supported input, mesh CAD closed within tolerance, check, write STL or 3MF."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.checks import (
    MeshChecks,
    check_mesh,
    closed_by_position,
    float32_degenerate_count,
    float32_joined,
    manifold3d_accepts,
)
from amprep.geometry.core.mesh import Mesh
from amprep.geometry.core.progress import ProgressFn
from amprep.geometry.io.stl import read_stl
from amprep.geometry.io.write import write_mesh
from amprep.geometry.measure.regularity import regularity_at, summarize
from amprep.geometry.measure.report import mesh_section
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import MeshResult, mesh_file
from amprep.geometry.parallel.forked import Forked
from amprep.jobs.common import STL_INFO, input_of, is_cad, model_info, provenance


@dataclass(frozen=True, eq=False)
class ConvertResult:
    """A converted part: the mesh, its checks and how it was made (`meshing` is None for STL passthrough)."""

    mesh: Mesh
    input: dict[str, Any]
    checks: MeshChecks
    manifold3d: bool
    meshing: MeshResult | None
    provenance: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    float32_degenerate: int = 0  # triangles degenerate only after rounding to the file's float32 coordinates
    float32_joined: int = 0  # vertices that share their float32 position with another (solids that touch)
    nonmanifold_by_position: int = 0  # non-manifold edges once vertices are joined by their float32 position
    regularity: dict[str, Any] = field(default_factory=dict)  # paper 000's measures: {angle, area, edge: {mean, bins}}

    @property
    def closed_by_position(self) -> bool:
        """Closed by index and still closed once vertices are joined by their float32 position, as a reader of an STL
        (which has no indices) joins them; a 3MF keeps each solid its own object and its indices."""
        return closed_by_position(self.checks, self.nonmanifold_by_position)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary of the conversion (the `convert` part of a job's report)."""
        c = self.checks
        out: dict[str, Any] = {
            "input": self.input,
            "mesh": mesh_section(self.mesh, c, self.manifold3d)
            .with_extra(float32_degenerate_triangles=self.float32_degenerate)
            .with_position(self.float32_joined, self.nonmanifold_by_position).to_json(),
            "regularity": self.regularity,
            "provenance": self.provenance,
            "notes": self.notes,
        }
        if self.meshing is not None:
            m = self.meshing
            out["meshing"] = {
                "tolerance": m.tolerance,
                "max_chordal_error": m.max_error,
                "within_tolerance": m.within_tolerance,
                "fallback_faces": {str(k): v for k, v in sorted(m.fallback_faces.items()) if v != "quality"},
                "faces_by_method": dict(sorted(Counter(f.meshed_by for f in m.mesh.faces).items())),
                "unmeshed_faces": list(m.unmeshed_faces),
                "estimated_triangles": m.estimated_triangles,
                "brep_gap": m.brep_gap,
                "seat_move": m.seat_move,
            }
        return out


#: a B-rep gap above this × the tolerance is named in the notes, with whether the faces beside it kept the tolerance
GAP_NOTE = 0.1

#: an edge node's move to join its faces above the tolerance and this × the B-rep's gap is named in the notes: a gap g
#: across the faces moves their nodes up to 2g (weld.SEAT_REACH), so a larger move is along the faces' surfaces
MOVE_OVER_GAP = 4.0

#: output checks of a mesh this large run beside manifold3d's in a forked child (forking costs ~10 ms)
FORK_CHECKS_MIN = 100_000


def output_checks(mesh: Mesh) -> tuple[MeshChecks, int, tuple[int, int]]:
    """(check_mesh, float32_degenerate_count, float32_joined) of a mesh."""
    degenerate = np.zeros(mesh.n_triangles, bool)
    checks = check_mesh(mesh, degenerate)
    return checks, float32_degenerate_count(mesh, degenerate), float32_joined(mesh, checks.nonmanifold_edges)


def convert(path: str | Path, params: MeshParams = MeshParams(), progress: ProgressFn | None = None) -> ConvertResult:
    """Read `path` and return its closed mesh within tolerance (CAD) or its checked mesh (STL passthrough)."""
    params.validate()
    fmt, info = input_of(path)
    notes: list[str] = []
    meshing = None
    if is_cad(fmt):
        model, meshing = mesh_file(path, fmt, params, progress)
        info.update(model_info(model))
        if model.units == "none":
            notes.append("the file declares no length unit: read as millimetres")
        if model.sewn:
            notes.append("loose faces were sewn into shells")
        notes.extend(model.notes)
        mesh = meshing.mesh
        if meshing.unmeshed_faces:
            notes.append(f"{len(meshing.unmeshed_faces)} face(s) could not be meshed")
        if meshing.brep_gap > GAP_NOTE * meshing.tolerance:
            notes.append(f"the CAD's faces miss their shared edges by up to {meshing.brep_gap:.3g} mm: the mesh is closed "
                         "on one point per edge node and measured from every face, so the gap counts in its chordal "
                         "error; " + ("the faces beside it were meshed finer to keep the tolerance" if meshing.within_tolerance else
                                      "no mesh closed on those nodes keeps the tolerance there: fix the CAD's gap or "
                                      "ask for a tolerance over twice it"))
        if meshing.seat_move > max(meshing.tolerance, MOVE_OVER_GAP * meshing.brep_gap):
            notes.append(f"the CAD's faces disagree on where their shared edges run by up to {meshing.seat_move:.3g} mm "
                         "along their surfaces, more than the tolerance: each edge node was joined at one point where "
                         "they meet, so an edge of the mesh may lie that far from where one of its faces puts it (the "
                         "chordal error is measured after the join); the CAD's edges are not same-parameter there")
    else:
        mesh = read_stl(path)
        info.update(STL_INFO)
        notes.append("STL input passed through: no unit in the file, values taken as millimetres")
    if mesh.n_triangles == 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the model produced no triangles")
    # our own checks in a forked child while manifold3d (which holds the GIL) runs here
    own = Forked(output_checks, mesh, fork=mesh.n_triangles >= FORK_CHECKS_MIN)
    ok3d = manifold3d_accepts(mesh)
    quality = summarize(regularity_at(mesh.vertices, mesh.triangles)).as_dict()  # here: the child's checks take longer
    try:
        checks, rounded, (joined, by_position) = own.result()
    except AmprepError:  # the child died: check here
        checks, rounded, (joined, by_position) = output_checks(mesh)
    if by_position > checks.nonmanifold_edges:
        notes.append(f"{joined} vertices share their float32 position with another vertex (solids that touch, or "
                     f"slivers the rounding collapses): a reader that joins an STL's vertices by position sees "
                     f"{by_position} non-manifold edges (a 3MF keeps each solid its own object)")
    if rounded:
        notes.append(f"{rounded} triangle(s) become degenerate when rounded to the float32 coordinates STL and 3MF "
                     "store (a part far from the origin at a micron tolerance)")
    if not checks.closed:
        notes.append(f"the mesh is open: {checks.boundary_edges} boundary and {checks.nonmanifold_edges} non-manifold edges")
    return ConvertResult(mesh, info, checks, ok3d, meshing, provenance(params if meshing else None), notes, rounded,
                         joined, by_position, quality)


def header_text(result: ConvertResult) -> str:
    """≤ 80-character STL header naming the tools and parameters that made the mesh."""
    p = result.provenance
    text = f"amprep {p['amprep']} occt {p['occt']} cq {p['cadquery']}"
    if result.meshing is not None:
        params = p["params"]
        mesher = params["algorithm"] if params.get("mesher", "occt") == "occt" else params["mesher"]
        text += f" tol {result.meshing.tolerance:g}mm ang {params['angular']:g} {mesher}"
    return text[:80]


def write_result(result: ConvertResult, out: str | Path, ascii: bool = False) -> dict[str, Any]:
    """Write the mesh by the output's extension (.stl binary or ASCII, .3mf); returns what was written."""
    return write_mesh(result.mesh, out, header_text(result), result.input.get("sha256", ""), ascii)
