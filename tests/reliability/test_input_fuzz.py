"""A fuzz of what reads strangers' bytes, bounded in examples and derandomised (the same cases every run): the format
sniffer, the STL reader and the CAD reading path (sniff, then read and prepare in a forked child, as a job does).
Whatever the bytes, the answer is a result or an AmprepError with a stable code: never another exception, a hang or
a dead process."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.formats import sniff_bytes, sniff_path
from amprep.geometry.io.stl import read_stl
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.read_ahead import read_and_prepare_ahead
from tests.conftest import corpus

BOUNDED = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                   suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
#: what a reader may answer besides a result
READ_CODES = {ErrorCode.EMPTY_MODEL, ErrorCode.UNSUPPORTED_FORMAT, ErrorCode.UNREADABLE_CAD, ErrorCode.UNREADABLE_MESH,
              ErrorCode.OUTPUT_TOO_LARGE}
HEADS = [b"ISO-10303-21;", b"solid x\n", b"DBRep_DrawableShape\n", b"Open CASCADE Topology V3",
         b"                                                                        S      1\n", b"PK\x03\x04", b""]


def _mutated(data: bytes, cuts: list[tuple[int, int, bytes]]) -> bytes:
    """The bytes with each (position, length, replacement) applied in turn (positions taken modulo the length)."""
    out = bytearray(data)
    for pos, length, new in cuts:
        at = pos % (len(out) + 1)
        out[at:at + length] = new
    return bytes(out)


_CUTS = st.lists(st.tuples(st.integers(0, 10**7), st.integers(0, 64), st.binary(max_size=16)), max_size=6)


@BOUNDED
@given(head=st.sampled_from(HEADS), body=st.binary(max_size=600), size=st.integers(0, 10**9))
def test_sniffer_names_a_format_or_refuses(head, body, size):
    try:
        fmt = sniff_bytes(head + body, size)
    except AmprepError as exc:
        assert exc.code in (ErrorCode.EMPTY_MODEL, ErrorCode.UNSUPPORTED_FORMAT)
        return
    assert fmt in ("step", "iges", "brep", "stl")


def _binary_stl(tris: np.ndarray, count: int) -> bytes:
    rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tris
    return b"\0" * 80 + struct.pack("<I", count) + rec.tobytes()


@BOUNDED
@given(n=st.integers(0, 40), lie=st.integers(-3, 3), cuts=_CUTS, special=st.sampled_from([0.0, np.nan, np.inf, 1e38]))
def test_stl_reader_reads_or_refuses(tmp_path_factory, n, lie, cuts, special):
    rng = np.random.default_rng(n)
    tris = rng.uniform(-5, 5, (n, 3, 3)).astype(np.float32)
    if n:
        tris[0, 0, 0] = special
    data = _mutated(_binary_stl(tris, max(n + lie, 0)), cuts)
    path = tmp_path_factory.mktemp("stl") / "f.stl"
    path.write_bytes(data)
    try:
        mesh = read_stl(path)
    except AmprepError as exc:
        assert exc.code in READ_CODES, exc
        return
    assert np.isfinite(mesh.vertices).all() and (mesh.triangles < mesh.n_vertices).all()


@BOUNDED
@given(cuts=_CUTS, ascii_head=st.booleans())
def test_ascii_stl_reader_reads_or_refuses(tmp_path_factory, cuts, ascii_head):
    text = ("solid t\n" if ascii_head else "") + "".join(
        f"facet normal 0 0 1\nouter loop\nvertex {i} 0 0\nvertex {i + 1} 0 0\nvertex {i} 1 0\nendloop\nendfacet\n"
        for i in range(5)) + "endsolid t\n"
    path = tmp_path_factory.mktemp("astl") / "f.stl"
    path.write_bytes(_mutated(text.encode(), cuts))
    try:
        read_stl(path)
    except AmprepError as exc:
        assert exc.code in READ_CODES, exc


SEEDS = {"step": corpus("cq_cube_cylinder_colors.step"), "iges": corpus("bspline_45_faces.iges")}


@settings(max_examples=25, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(sorted(SEEDS)), cuts=_CUTS, keep=st.floats(0.05, 1.0))
def test_cad_reading_path_reads_or_refuses(tmp_path_factory, kind, cuts, keep):
    """A real STEP or IGES, truncated and with bytes replaced, read as a job reads it (sniffed, then read and
    prepared in a forked child): a crash of OCCT's reader is unreadable_cad, not this process's end."""
    data = Path(SEEDS[kind]).read_bytes()
    data = _mutated(data[: max(1, int(len(data) * keep))], cuts)
    path = tmp_path_factory.mktemp("cad") / f"f.{kind}"
    path.write_bytes(data)
    try:
        fmt = sniff_path(path)
        if fmt in ("step", "iges", "brep"):
            read_and_prepare_ahead(path, fmt, MeshParams(tolerance=0.5))
    except AmprepError as exc:
        assert exc.code in READ_CODES, exc
