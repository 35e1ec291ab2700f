"""numpy arrays from OCCT values (a point, vector or direction as (3,), a TColStd/TColgp 1-D array as (n,)), and
1-D OCCT arrays from numpy."""

from __future__ import annotations

import numpy as np


def vec(p) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(3,) X, Y, Z of a gp_Pnt, gp_Vec, gp_Dir or gp_XYZ."""
    return np.array([p.X(), p.Y(), p.Z()])


def to_array1(values: np.ndarray, cls):  # type: ignore[no-untyped-def]
    """A 1-D OCCT array of class `cls` (TColStd_Array1OfReal, …OfInteger) holding values (n,), indexed from 1."""
    out = cls(1, len(values))
    for i, v in enumerate(np.asarray(values).tolist(), 1):
        out.SetValue(i, v)
    return out


def array1(arr) -> np.ndarray:  # type: ignore[no-untyped-def]
    """(n,) float values of a 1-D OCCT array, Lower() to Upper()."""
    return np.array([arr.Value(i) for i in range(arr.Lower(), arr.Upper() + 1)], dtype=float)
