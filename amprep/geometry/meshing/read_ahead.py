"""Read and prepare a CAD file (prepare.py: tolerance, BRepMesh) in a forked child: a file that crashes OCCT ends the
child, not this process, and meanwhile this process loads the compiled kernels (reading a STEP, OCCT's meshing and
numba's start-up all hold the GIL, so only two processes overlap them). The child hands the meshed shape back in
OCCT's binary BREP (triangulations and edge polygons included, read back in ~20 ms for CTC-02), so the caller
continues exactly as if it had read and meshed it itself."""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path

from OCP.BinTools import BinTools, BinTools_FormatVersion
from OCP.TopoDS import TopoDS_Shape

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.cad.instances import find_instancing
from amprep.geometry.cad.read import model_from_shape, read_cad
from amprep.geometry.core.progress import ProgressFn
from amprep.geometry.measure.chordal import kernels_warm, warm_kernels
from amprep.geometry.meshing.brepmesh import occt_pool_untouched
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.prepare import Prepared, prepare
from amprep.geometry.parallel.forked import Forked, fork_available

#: a file this large takes the child over ~0.5 s to read (STEP parses at 1.5–5 MB/s here), which hides numba's
#: import and first dispatch (~0.65 s), and its part is large: the kernels are warmed at once
WARM_NOW_BYTES = 1_500_000
#: a smaller file's kernels are warmed only when the child is still at work after this many seconds, i.e. BRepMesh
#: is making many triangles. Warming costs the parent ~0.35 s of numba import it cannot stop: a part whose child
#: ends before that is over pays it for kernels it rarely needs (a 0.6 MB part library STEP, read and meshed in
#: 0.3 s, took 0.55 s with the warm started at 0.15 s, 0.34 s without)
WARM_AFTER = 0.5


def warm_delay(path: str | Path) -> float:
    """Seconds to let the reading child work before warming the kernels: 0 for a file of WARM_NOW_BYTES or more,
    WARM_AFTER for a smaller one."""
    return 0.0 if Path(path).stat().st_size >= WARM_NOW_BYTES else WARM_AFTER


def read_and_prepare(path: str | Path, fmt: str, params: MeshParams) -> Prepared:
    """A CAD file read and prepared (its tolerance worked out, BRepMesh run at it) in this process, passed through
    the same binary BREP the reading child sends back: the result does not depend on which process read it (the
    round trip can move a coordinate by 1e-20)."""
    return _received(_child(str(path), fmt, params), fmt)


_Sent = tuple[bytes, str, bool, float, tuple[int, ...], int, bool, tuple[str, ...], tuple[dict, ...]]


def _child(path: str, fmt: str, params: MeshParams) -> _Sent:
    p = prepare(read_cad(path, fmt), params)
    buf = io.BytesIO()
    BinTools.Write_s(p.model.shape, buf, True, False, BinTools_FormatVersion.BinTools_FormatVersion_VERSION_3)
    return (buf.getvalue(), p.model.units, p.model.sewn, p.tolerance, p.own, p.estimated, p.instancing is not None,
            p.model.notes, p.model.unsupported)


def _received(sent: _Sent, fmt: str) -> Prepared:
    """The Prepared the child made, from its BREP: the instancing is found again on the received shape (the same
    solids; instances share their faces' triangulations, so every placement arrives meshed)."""
    data, units, sewn, tol, own, estimated, instanced, notes, unsupported = sent
    shape = TopoDS_Shape()
    BinTools.Read_s(shape, io.BytesIO(data))
    if shape.IsNull():
        raise AmprepError(ErrorCode.MESHING_FAILED, "the meshed shape did not come back from the reading process")
    model = model_from_shape(shape, fmt, units, sewn, notes, unsupported)
    inst = find_instancing(model) if instanced else None
    return Prepared(model, tol, own if inst is not None or not instanced else (), estimated, inst)


def read_and_prepare_ahead(path: str | Path, fmt: str, params: MeshParams,
                           progress: ProgressFn | None = None) -> Prepared:
    """read_and_prepare in a forked child, wherever the platform forks (a Celery worker too): a file that crashes
    OCCT ends the child, not this process, and is unreadable_cad. Meanwhile this process warms the kernels (when
    they are not warm yet, loaded or not, and it may use a second core; after warm_delay), then calls
    progress("reading", 0) every half second, so a cancel or a time limit raised there stops the child at once.
    OCCT's parallel meshing runs in the child only when this process never started OCCT's thread pool (it gives the
    same mesh either way)."""
    child_params = replace(params, parallel=params.parallel and occt_pool_untouched())
    job = Forked(_child, str(path), fmt, child_params, isolate=True,
                 died=(ErrorCode.UNREADABLE_CAD, f"OCCT crashed reading or meshing the {fmt.upper()} file"))
    if not job.forked:
        return read_and_prepare(path, fmt, params)
    try:
        if not kernels_warm() and fork_available() and not job.ready(warm_delay(path)):
            warm_kernels(stop=job.ready)
        while not job.ready(0.5):
            if progress:
                progress("reading", 0.0)
        return _received(job.result(), fmt)
    finally:
        job.kill()  # a cancel, a time limit or any error here: the child does not read on (no-op once collected)
