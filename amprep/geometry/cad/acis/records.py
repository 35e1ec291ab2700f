"""ACIS records from SAT text or SAB bytes: the header, and each record's name and tokens, decoded on demand.

Both encodings become one token stream, read field by field by entities.Cursor: SAT's tokens stay the words written
(`$12`, `4.5`, `forward`, `{`), SAB's are typed: `Ref` (an entity reference, -1 for none), int, float, `Enum`, str
(an identifier such as `nubs`), `Flag` (a logical, whose word depends on the field) and the `OPEN` / `CLOSE` braces;
a counted string is `Text` in both. Vectors (SAB's position and direction tags) become three floats. Records are
split at once (one regular-expression search per record) and tokenised only when read, so a file's attributes,
most of its records, cost nothing. Every malformed byte is `unreadable_cad`.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.formats import sat_start

SAB_SIGNATURES = (b"ACIS BinaryFile", b"ASM BinaryFile4", b"ASM BinaryFile")


class Ref(int):
    """An entity reference `$n` (-1: none)."""


class Text(str):
    """A counted string (`@n chars` in SAT, a string tag in SAB)."""


class Flag(int):
    """SAB's logical: 1 is the field's second word (reversed, reverse_v, double, in, F of an interval)."""


class Enum(int):
    """SAB's enumeration value (a word in SAT: open, closed, periodic, full, none, …)."""


class Brace(str):
    """`{` or `}` around a subtype."""


OPEN, CLOSE = Brace("{"), Brace("}")
Token = Ref | int | float | str


def fail(message: str) -> AmprepError:
    return AmprepError(ErrorCode.UNREADABLE_CAD, f"ACIS: {message}")


@dataclass
class Header:
    """Version (e.g. 700, 21800), record and body counts, writer, length unit in mm (as written; ≤ 0: unstated)."""

    version: int
    records: int = 0
    bodies: int = 0
    product: str = ""
    acis: str = ""
    unit_mm: float = 1.0
    binary: bool = False

    @property
    def asm(self) -> bool:
        """Autodesk's ASM fork (versions 20800 and up) drops the fields Spatial's ACIS 10+ adds to every record."""
        return self.version >= 20000 or self.acis.startswith("ASM")


@dataclass
class Records:
    """Record i's name and its tokens (read lazily through `tokens(i)`)."""

    header: Header
    names: list[str]
    _raw: list[object]
    _decode: object = field(repr=False)
    _cache: dict[int, list[Token]] = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.names)

    def tokens(self, i: int) -> list[Token]:
        """Tokens of record i after its name."""
        if not 0 <= i < len(self.names):
            raise fail(f"reference ${i} points outside the file's {len(self.names)} records")
        got = self._cache.get(i)
        if got is None:
            got = self._cache[i] = self._decode(self._raw[i])  # type: ignore[operator]
        return got


# ---------------------------------------------------------------- SAT (text)

_BOUNDARY = re.compile(r"@(\d+) |#")
_WORD = re.compile(r"\{|\}|[^\s{}]+")
_COUNTED = re.compile(r"\s*@(\d+) ")
_HEADER_STRING = re.compile(r"\s*@?(\d+) ?")


def _counted_strings(line: str) -> list[str]:
    """The strings of a SAT header line: `[@]n chars` repeated (AutoCAD writes `0` for an empty date)."""
    out, i = [], 0
    while i < len(line):
        m = _HEADER_STRING.match(line, i)
        if not m:
            break
        n = int(m.group(1))
        out.append(line[m.end():m.end() + n])
        i = m.end() + n
    return out


def _sat_decode(raw: object) -> list[Token]:
    """A SAT record's tokens as written (`$n`, numbers and words stay text: entities.Cursor reads them by field);
    `@n` strings become Text, braces their own tokens."""
    text = str(raw)
    if "@" not in text:
        return text.split() if "{" not in text and "}" not in text else _WORD.findall(text)  # type: ignore[return-value]
    out: list[Token] = []
    i = 0
    while i < len(text):
        m = _COUNTED.match(text, i)
        if m:
            n = int(m.group(1))
            out.append(Text(text[m.end():m.end() + n]))
            i = m.end() + n
            continue
        m = _WORD.search(text, i)
        if not m:
            break
        out.append(m.group(0))
        i = m.end()
    return out


def _split_name(text: str) -> tuple[str, str]:
    """(name, rest) of one SAT record; a leading `-n` sequence number is dropped."""
    parts = text.split(None, 2)
    if parts and parts[0].startswith("-") and parts[0][1:].isdigit():
        parts = parts[1:]
    if not parts:
        return "", ""
    return parts[0], (parts[1] + (" " + parts[2] if len(parts) > 2 else "")) if len(parts) > 1 else ""


def parse_sat(text: str) -> Records:
    """Header and records of SAT text (version from the first line; strings counted, `@n` or bare before 700)."""
    start = sat_start(text)
    if start is None:
        raise fail("no SAT header (version, record and body counts, then the writer and unit lines)")
    lines = text[start:].split("\n", 3)
    if len(lines) < 4:
        raise fail("the header is incomplete")
    head = lines[0].split()
    try:
        version = int(head[0])
    except (IndexError, ValueError):
        raise fail("the first line does not start with a version number") from None
    strings = _counted_strings(lines[1].strip())
    header = Header(version, *(_int(head, k) for k in (1, 2)), product=strings[0] if strings else "",
                    acis=strings[1] if len(strings) > 1 else "")
    try:
        header.unit_mm = float(lines[2].split()[0])
    except (IndexError, ValueError):
        raise fail("the third header line has no unit scale") from None
    body = lines[3]
    names: list[str] = []
    raw: list[object] = []
    pos, start, n = 0, 0, len(body)
    while pos < n:
        m = _BOUNDARY.search(body, pos)
        if m is None:
            break
        if m.group(0) != "#":
            pos = m.end() + int(m.group(1))
            continue
        name, rest = _split_name(body[start:m.start()])
        if name.startswith(("End-of-", "Begin-of-")):
            break
        names.append(name)
        raw.append(rest)
        pos = start = m.end()
    else:
        tail = body[start:].strip()
        if tail and not tail.startswith(("End-of-", "Begin-of-")):
            raise fail("the last record has no terminating '#' (the file is truncated)")
    return Records(header, names, raw, _sat_decode)


def _int(parts: list[str], k: int) -> int:
    try:
        return int(parts[k])
    except (IndexError, ValueError):
        return 0


# ---------------------------------------------------------------- SAB (binary)

_FIXED = {0x02: 1, 0x03: 2, 0x04: 4, 0x05: 4, 0x06: 8, 0x0C: 4, 0x13: 24, 0x14: 24, 0x15: 4, 0x16: 16, 0x17: 8}


class _Sab:
    """A cursor over SAB bytes (little-endian tags, ezdxf's and ACIS's numbering)."""

    def __init__(self, data: bytes, pos: int) -> None:
        self.data, self.pos = data, pos

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise fail("the binary data ends inside a record (the file is truncated)")
        b = self.data[self.pos:self.pos + n]
        self.pos += n
        return b

    def tag(self) -> int:
        return self.take(1)[0]

    def string(self, tag: int) -> str:
        width = {0x07: 1, 0x0D: 1, 0x0E: 1, 0x08: 2, 0x09: 4, 0x12: 4}[tag]
        n = int.from_bytes(self.take(width), "little")
        return self.take(n).decode("utf-8", "replace")

    def value(self, tag: int) -> object:
        if tag in (0x07, 0x08, 0x09, 0x12):
            return Text(self.string(tag))
        if tag == 0x04:
            return struct.unpack("<i", self.take(4))[0]
        if tag == 0x06:
            v = struct.unpack("<d", self.take(8))[0]
            return v
        raise fail(f"expected a header value, found tag 0x{tag:02x}")

    def record(self) -> tuple[str, list[Token]]:
        """(name, tokens) of the next record; the name joins the class chain (`plane` `surface` → plane-surface)."""
        name_parts: list[str] = []
        name = ""
        out: list[Token] = []
        while True:
            t = self.tag()
            if t == 0x11:
                return name, out
            if t == 0x0E:
                name_parts.append(self.string(t))
            elif t == 0x0D:
                name_parts.append(self.string(t))
                word = "-".join(name_parts)
                name_parts.clear()
                if not name:
                    name = word
                    if word.startswith(("End-of-", "Begin-of-")):
                        return name, out
                else:
                    out.append(word)  # a sub-record's class name (e.g. inside a subtype)
            elif t == 0x0C:
                out.append(Ref(struct.unpack("<i", self.take(4))[0]))
            elif t == 0x04:
                out.append(struct.unpack("<i", self.take(4))[0])
            elif t == 0x15:
                out.append(Enum(struct.unpack("<i", self.take(4))[0]))
            elif t == 0x06:
                out.append(struct.unpack("<d", self.take(8))[0])
            elif t in (0x13, 0x14):
                out.extend(struct.unpack("<3d", self.take(24)))
            elif t == 0x16:
                out.extend(struct.unpack("<2d", self.take(16)))
            elif t == 0x17:
                out.append(struct.unpack("<q", self.take(8))[0])
            elif t == 0x03:
                out.append(struct.unpack("<h", self.take(2))[0])
            elif t == 0x02:
                out.append(self.take(1)[0])
            elif t == 0x05:
                out.append(struct.unpack("<f", self.take(4))[0])
            elif t in (0x07, 0x08, 0x09, 0x12):
                s = self.string(t)
                out.append(s if t == 0x07 and s.isidentifier() else Text(s))
            elif t == 0x0A:
                out.append(Flag(1))
            elif t == 0x0B:
                out.append(Flag(0))
            elif t == 0x0F:
                out.append(OPEN)
            elif t == 0x10:
                out.append(CLOSE)
            else:
                raise fail(f"unknown binary tag 0x{t:02x} at byte {self.pos - 1}")


def parse_sab(data: bytes) -> Records:
    """Header and records of SAB bytes (`ACIS BinaryFile` or `ASM BinaryFile4`, then 4 int32 and tagged values)."""
    sig = next((s for s in SAB_SIGNATURES if data.startswith(s)), None)
    if sig is None:
        raise fail("not an ACIS binary file")
    cur = _Sab(data, len(sig))
    version, n_records, n_bodies, _flags = struct.unpack("<4i", cur.take(16))
    header = Header(version, n_records, n_bodies, binary=True)
    header.product = str(cur.value(cur.tag()))
    header.acis = str(cur.value(cur.tag()))
    cur.value(cur.tag())  # date
    unit = cur.value(cur.tag())
    header.unit_mm = float(unit) if isinstance(unit, (int, float)) else 1.0
    cur.value(cur.tag())  # resabs
    cur.value(cur.tag())  # resnor
    names: list[str] = []
    raw: list[object] = []
    while cur.pos < len(data):
        name, tokens = cur.record()
        if name.startswith(("End-of-", "Begin-of-")):
            break
        if not name:
            raise fail("a binary record has no class name")
        names.append(name)
        raw.append(tokens)
    else:
        raise fail("the binary data has no End-of-ACIS-data marker (the file is truncated)")
    return Records(header, names, raw, lambda r: r)


def parse(data: bytes) -> Records:
    """SAB when the bytes start with its signature, SAT otherwise (text decoded as UTF-8, Latin-1 on failure)."""
    if data.startswith(SAB_SIGNATURES):
        return parse_sab(data)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return parse_sat(text.replace("\r\n", "\n").replace("\r", "\n"))
