"""The meshing parameters every mesher takes (a frozen dataclass: tolerance, angle, algorithm and switches)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.limits import DEFAULT_MAX_TRIANGLES, MIN_TOLERANCE

MESHERS = ("occt", "quality")


@dataclass(frozen=True)
class MeshParams:
    """Meshing parameters: `tolerance` mm (absolute chord deviation) or `relative` (fraction of the bounding-box
    diagonal, overrides tolerance), `angular` rad (the largest turn of one edge segment), `min_size` mm (BRepMesh's
    smallest edge; the quality mesher's floor for cutting edges to its faces' widths, never for the tolerance),
    `algorithm` delabella | watson, `max_triangles` the most the output may have by the estimate made before meshing."""

    tolerance: float = 0.1
    relative: float | None = None
    angular: float = 0.5
    min_size: float = 0.0
    algorithm: str = "delabella"
    mesher: str = "occt"  # occt: BRepMesh, mended by ours; quality: every face by ours (seed 000: CDT, (u,v) grid)
    parallel: bool = True
    enforce_tolerance: bool = True
    force_fallback: bool = False
    check_order: int = 6  # the barycentric grid order the faces' chordal error is checked on
    occt_edges: bool = False  # every edge at half the tolerance and angle, as BRepMesh does (brepmesh.py)
    own_large_faces: bool = True  # mesh large torus faces ourselves, not with BRepMesh (prepare.py)
    occt_surface_control: bool = False  # OCCT's own deflection check of face interiors (ours replaces it)
    max_triangles: int = DEFAULT_MAX_TRIANGLES  # refuse (output_too_large) a model estimated to mesh to more
    mesh_instances_once: bool = True  # an assembly of placed copies of fewer solids: mesh each once (instances.py)

    @property
    def all_own(self) -> bool:
        """True when every face is meshed by our own mesher (mesher quality, or the tests' force_fallback)."""
        return self.force_fallback or self.mesher == "quality"

    @property
    def quality(self) -> bool:
        """True for the quality mesher: planes refined to a minimum angle, curved faces smoothed (face_mesher.py)."""
        return self.mesher == "quality"

    def validate(self) -> None:
        """Raise invalid_parameter for values no mesher can honour."""
        bad = None
        if not (self.tolerance >= MIN_TOLERANCE and np.isfinite(self.tolerance)):
            bad = f"tolerance must be a number of mm ≥ {MIN_TOLERANCE:g}, got {self.tolerance}"
        elif self.relative is not None and not (0 < self.relative < 1):
            bad = f"relative tolerance must be a fraction in (0, 1), got {self.relative}"
        elif not (0 < self.angular <= np.pi / 2):
            bad = f"angular deflection must be in (0, π/2] rad, got {self.angular}"
        elif self.min_size < 0:
            bad = f"min size must be ≥ 0, got {self.min_size}"
        elif self.algorithm not in ("delabella", "watson"):
            bad = f"algorithm must be delabella or watson, got {self.algorithm}"
        elif self.mesher not in MESHERS:
            bad = f"mesher must be one of {', '.join(MESHERS)}, got {self.mesher}"
        elif not (1 <= self.check_order <= 30):
            bad = f"check order must be 1..30, got {self.check_order}"
        elif not (isinstance(self.max_triangles, int) and self.max_triangles >= 1):
            bad = f"max triangles must be an integer ≥ 1, got {self.max_triangles}"
        if bad:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, bad)
