"""Run OCCT's BRepMesh on a shape with edges discretised as the tolerance needs, not twice as finely.

BRepMesh discretises every edge at half the linear and half the angular deflection it is given (its
CurveTessellator's "precise" values): a cylinder r=10 comes out at 0.49× the tolerance, with ~1.4× the segments,
and a 3.1 mm hole at 0.1 mm with 26 segments where the angle asked for allows 13. That margin only pays on faces
curved both ways, whose triangles along an edge add the surface's bulge to the edge's own sagitta. So the faces
are meshed in two passes:
1. the faces not ruled (is_ruled), edges at half the tolerance as OCCT does them;
2. the whole shape, edges at EDGE_TARGET × tolerance. Pass 1's faces are kept (BRepMesh reuses a triangulation
   and its edge polygons whose deflection is within 1.1× of what is asked), and an edge one of them shares keeps
   pass 1's finer points; every other edge and face is meshed here.
Every edge segment turns through at most the `angular` asked for (pass 2 × BRepMesh's halving), face interiors are
meshed at the tolerance; the chordal error of every face is measured afterwards, so the margin is not needed to
keep the promise (mesher.py re-meshes any face over the tolerance).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.BRepTools import BRepTools
from OCP.IMeshTools import (
    IMeshTools_MeshAlgoType_Delabella,
    IMeshTools_MeshAlgoType_Watson,
    IMeshTools_Parameters,
)
from OCP.TopAbs import TopAbs_FACE
from OCP.TopoDS import TopoDS, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape

from amprep.geometry.cad.estimate import OCCT_EDGE_FACTOR, occt_min_size
from amprep.geometry.cad.surfaces import is_ruled
from amprep.geometry.cad.topology import compound, explore
from amprep.geometry.meshing.params import MeshParams

#: edges where only ruled faces meet are discretised at this × the tolerance (their faces' error is about the
#: edges' sagitta; a little under 1 so that OCCT's face interiors, meshed at the tolerance, rarely exceed it)
EDGE_TARGET = 0.95


_pool_started = False  # True once this process ran BRepMesh in parallel (OCCT's thread pool then has threads)


def occt_pool_untouched() -> bool:
    """True when this process has not run OCCT in parallel, as far as it can tell (no parallel run_brepmesh, no
    cadquery imported): a forked child may then start OCCT's thread pool itself. After a fork the pool's threads
    of the parent are gone but its state says they exist, and a parallel BRepMesh in the child waits for ever."""
    return not _pool_started and "cadquery" not in sys.modules


def run_brepmesh(shape: TopoDS_Shape, tolerance: float, params: MeshParams,
                 skip: Sequence[TopoDS_Face] = ()) -> None:
    """Clear any earlier triangulation (a stale one is silently reused otherwise), then BRepMesh every face of the
    shape but `skip`: in the two passes of the module's docstring, or with params.occt_edges in one pass as OCCT
    does by default (every edge at half the tolerance and half the angle). Face interiors go without OCCT's surface
    deflection control unless params.occt_surface_control."""
    BRepTools.Clean_s(shape)
    left_out = TopTools_IndexedMapOfShape()
    for f in skip:
        left_out.Add(f)
    faces = [f for f in explore(shape, TopAbs_FACE, TopoDS.Face_s) if not left_out.Contains(f)]
    if not faces:
        return
    if params.occt_edges:
        _brepmesh(compound(faces), tolerance, params, tolerance, params.angular)
        return
    edge_angle = params.angular / OCCT_EDGE_FACTOR
    curved = [f for f in faces if not is_ruled(f)]
    if curved:
        _brepmesh(compound(curved), tolerance, params, tolerance, edge_angle)
    if len(curved) < len(faces):
        _brepmesh(compound(faces), tolerance, params, EDGE_TARGET * tolerance / OCCT_EDGE_FACTOR, edge_angle)


def _brepmesh(shape: TopoDS_Shape, tolerance: float, params: MeshParams, deflection: float, angle: float) -> None:
    """BRepMesh with `deflection` and `angle` for edges (which it halves), the tolerance and OCCT's default interior
    angle (2 × params.angular) for face interiors."""
    p = IMeshTools_Parameters()
    p.Deflection = deflection
    p.Angle = angle
    p.DeflectionInterior = tolerance
    p.AngleInterior = 2 * params.angular
    p.ForceFaceDeflection = True  # a face's deflection is DeflectionInterior, not its wires' mean deflection
    p.Relative = False
    p.InParallel = params.parallel
    if params.parallel:
        global _pool_started
        _pool_started = True
    p.MinSize = occt_min_size(tolerance, params.min_size)
    p.MeshAlgo = IMeshTools_MeshAlgoType_Delabella if params.algorithm == "delabella" else IMeshTools_MeshAlgoType_Watson
    # OCCT's interior deflection control (test points, insert, re-triangulate, repeat) is 90 % of its time on
    # free-form parts and still leaves faces over tolerance; our per-triangle check and local insertion replace it
    p.ControlSurfaceDeflection = params.occt_surface_control
    BRepMesh_IncrementalMesh(shape, p)
