"""Shared test fixtures: the real-parts corpus in ../shared/corpus and reference solids built with cadquery."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

CORPUS = Path(os.environ.get("AMPREP_CORPUS", Path(__file__).resolve().parents[2] / "shared" / "corpus"))

CAD_FILES = sorted(p.name for p in CORPUS.glob("*") if p.suffix.lower() in (".step", ".stp", ".iges", ".igs", ".brep"))
STL_FILES = sorted(p.name for p in CORPUS.glob("*.stl"))
OPEN_CAD = {"sunglasses_lens_inch.igs", "bspline_45_faces.iges", "dtmb5415_bow_hull.iges"}


def corpus(name: str) -> Path:
    path = CORPUS / name
    if not path.exists():
        pytest.fail(f"corpus file missing: {path} (set AMPREP_CORPUS)")
    return path


@pytest.fixture(scope="session")
def reference_solids():
    """Exact solids built here: name → TopoDS_Shape (every analytic surface type and a B-spline loft)."""
    import cadquery as cq

    loft = (cq.Workplane("XY").circle(8).workplane(offset=10).rect(10, 6).workplane(offset=10).circle(5)
            .loft(combine=True).val())
    return {
        "sphere": cq.Solid.makeSphere(12, angleDegrees1=-90, angleDegrees2=90).wrapped,
        "torus": cq.Solid.makeTorus(20, 5).wrapped,
        "cylinder": cq.Solid.makeCylinder(10, 30).wrapped,
        "cone": cq.Solid.makeCone(10, 0, 20).wrapped,
        "filleted_block": cq.Workplane().box(30, 20, 10).edges().fillet(3).val().wrapped,
        "bspline_loft": loft.wrapped,
        "plate_with_holes": cq.Workplane().box(40, 30, 5).faces(">Z").workplane().rarray(20, 10, 2, 2)
        .hole(4).val().wrapped,
    }


@pytest.fixture
def meshed_faces(monkeypatch):
    """enforce.mesh_face counted from here on: (started, finished), one entry per call begun and per face it
    finished (its triangle count); clear them to count a later run only."""
    from amprep.geometry.meshing import enforce

    started: list[int] = []
    finished: list[int] = []
    real = enforce.mesh_face

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        started.append(1)
        patch = real(*args, **kwargs)
        finished.append(len(patch.tris))
        return patch

    monkeypatch.setattr(enforce, "mesh_face", counted)
    return started, finished


@pytest.fixture
def touching_step(tmp_path) -> Path:
    """A STEP of two 10 mm boxes face to face (an assembly whose solids touch): closed by index, joined by position."""
    import cadquery as cq

    path = tmp_path / "touching.step"
    boxes = cq.Compound.makeCompound([cq.Solid.makeBox(10, 10, 10), cq.Solid.makeBox(10, 10, 10, cq.Vector(10, 0, 0))])
    cq.exporters.export(cq.Workplane().add(boxes), str(path))
    return path
