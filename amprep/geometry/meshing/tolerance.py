"""The chord tolerance in millimetres: `tolerance`, or `relative` × the model's bounding-box diagonal."""

from __future__ import annotations

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRepBndLib import BRepBndLib

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.read import CadModel
from amprep.geometry.core.limits import MIN_TOLERANCE
from amprep.geometry.meshing.params import MeshParams


def bbox_diagonal(model: CadModel, meshed: bool = False) -> float:
    """Diagonal of the model's bounding box (mm): the optimal (exact-geometry) box, or with `meshed` the box of
    its triangulations (milliseconds where the optimal box of a free-form part takes seconds)."""
    box = Bnd_Box()
    if meshed:
        BRepBndLib.Add_s(model.shape, box, True)
    else:
        BRepBndLib.AddOptimal_s(model.shape, box, False, False)
    if box.IsVoid():
        return 0.0
    x0, y0, z0, x1, y1, z1 = box.Get()
    return float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))


def absolute_tolerance(model: CadModel, params: MeshParams) -> float:
    """The linear tolerance in mm: `tolerance`, or `relative` × bounding-box diagonal."""
    if params.relative is None:
        return params.tolerance
    diag = bbox_diagonal(model)
    if diag <= 0:
        raise AmprepError(ErrorCode.EMPTY_MODEL, "the model has an empty bounding box")
    tol = params.relative * diag
    if tol < MIN_TOLERANCE:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"relative tolerance {params.relative:g} of this part's "
                          f"{diag:.4g} mm diagonal is {tol:.3g} mm, under the finest of {MIN_TOLERANCE:g} mm")
    return tol
