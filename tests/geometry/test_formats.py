import struct

import pytest

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.formats import sniff_bytes, sniff_path
from tests.conftest import CAD_FILES, STL_FILES, corpus

EXPECTED = {".step": "step", ".stp": "step", ".iges": "iges", ".igs": "iges", ".brep": "brep", ".stl": "stl"}


@pytest.mark.parametrize("name", CAD_FILES + STL_FILES)
def test_corpus_format_from_bytes(name, tmp_path):
    src = corpus(name)
    renamed = tmp_path / "upload.bin"  # the name says nothing: the bytes decide
    renamed.write_bytes(src.read_bytes())
    assert sniff_path(renamed) == EXPECTED[src.suffix.lower()]


def test_binary_stl_whose_header_says_solid():
    head = b"solid made by SolidWorks".ljust(80) + struct.pack("<I", 1) + bytes(50)
    assert sniff_bytes(head, len(head)) == "stl"


@pytest.mark.parametrize("data,code", [
    (b"", ErrorCode.EMPTY_MODEL),
    (b"   \n\n", ErrorCode.EMPTY_MODEL),
    (b"hello, this is not CAD at all", ErrorCode.UNSUPPORTED_FORMAT),
    (b"PK\x03\x04 zipped", ErrorCode.UNSUPPORTED_FORMAT),
])
def test_bad_bytes_have_stable_codes(data, code):
    with pytest.raises(AmprepError) as err:
        sniff_bytes(data, len(data))
    assert err.value.code == code
