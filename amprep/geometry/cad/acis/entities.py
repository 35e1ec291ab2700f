"""ACIS entities decoded from records: topology (body … point), transforms, and the geometry the builder uses.

Field layouts by version, as ACIS writes them (SAT and SAB alike): every entity starts with its attribute
reference; from 7.0 (700) a history integer follows; Spatial's ACIS from 10.0 (1000, not Autodesk's ASM) adds
another integer; topology and geometry then carry a pattern reference (700+). Fields a writer appends after the ones
read here (Cubit's bounding boxes, ASM's extra integers) are ignored.
"""

from __future__ import annotations

from dataclasses import dataclass

from amprep.geometry.cad.acis.records import CLOSE, OPEN, Flag, Records, Ref, Text, Token, fail


def number(tok: Token) -> float | None:
    """The value of a number token (SAT text or SAB's int and double), None for anything else."""
    t = type(tok)
    if t is float or t is int:
        return float(tok)
    if t is str and tok[:1] not in ("$", "@") and tok not in ("I", "F", "T", "{", "}"):
        try:
            return float(tok)  # type: ignore[arg-type]
        except ValueError:
            return None
    return None


def is_int(tok: Token) -> bool:
    """True for a plain integer token (SAT digits, SAB's int), not a reference, logical or enumeration."""
    t = type(tok)
    if t is int:
        return True
    return t is str and (tok.isdigit() or (tok[:1] == "-" and tok[1:].isdigit()))  # type: ignore[union-attr]


class Cursor:
    """Typed reads over one record's tokens; every mismatch is unreadable_cad naming the record."""

    def __init__(self, tokens: list[Token], where: str, pos: int = 0) -> None:
        self.t, self.where, self.i = tokens, where, pos

    def _next(self) -> Token:
        if self.i >= len(self.t):
            raise fail(f"{self.where} ends early")
        tok = self.t[self.i]
        self.i += 1
        return tok

    def peek(self) -> Token | None:
        return self.t[self.i] if self.i < len(self.t) else None

    def ref(self) -> int:
        tok = self._next()
        if isinstance(tok, Ref):
            return int(tok)
        if type(tok) is str and tok[:1] == "$":
            try:
                return int(tok[1:])
            except ValueError:
                pass
        raise fail(f"{self.where}: expected an entity reference, found {str(tok)[:20]!r}")

    def ref_after_ints(self) -> int:
        """The next reference, past any plain integers some writers put before it."""
        while self.i < len(self.t) and is_int(self.t[self.i]):
            self.i += 1
        return self.ref()

    def num(self) -> float:
        tok = self._next()
        v = number(tok)
        if v is None:
            raise fail(f"{self.where}: expected a number, found {str(tok)[:20]!r}")
        if v != v or v in (float("inf"), float("-inf")):
            raise fail(f"{self.where}: a non-finite number")
        return v

    def number_next(self) -> bool:
        """True when the next token is a number."""
        return self.i < len(self.t) and number(self.t[self.i]) is not None

    def vec(self) -> tuple[float, float, float]:
        return self.num(), self.num(), self.num()

    def flag(self, true_word: str, false_word: str) -> bool:
        """True for `true_word` (or SAB's logical 1), False for `false_word` (0); pre-400 writers' 1 and 0 too."""
        tok = self._next()
        if isinstance(tok, Flag):
            return bool(tok)
        if tok == true_word or tok == "1" or (type(tok) is int and tok == 1):
            return True
        if tok == false_word or tok == "0" or (type(tok) is int and tok == 0):
            return False
        raise fail(f"{self.where}: expected {false_word} or {true_word}, found {str(tok)[:20]!r}")

    def bound(self) -> float | None:
        """One end of an interval: `I` (infinite) → None, `F x` → x."""
        return self.num() if self.flag("F", "I") else None

    def skip(self, n: int) -> None:
        self.i += n

    def subtype(self) -> list[Token]:
        """The tokens of a `{ … }` subtype (braces nested inside kept), the cursor past its `}`."""
        tok = self._next()
        if tok != "{" or isinstance(tok, Text):
            raise fail(f"{self.where}: expected a subtype '{{'")
        start, depth = self.i, 1
        while depth:
            tok = self._next()
            if tok == "{" and not isinstance(tok, Text):
                depth += 1
            elif tok == "}" and not isinstance(tok, Text):
                depth -= 1
        return self.t[start:self.i - 1]


@dataclass(frozen=True)
class Body:
    lump: int
    wire: int
    transform: int


@dataclass(frozen=True)
class Lump:
    next: int
    shell: int


@dataclass(frozen=True)
class Shell:
    next: int
    face: int


@dataclass(frozen=True)
class Face:
    next: int
    loop: int
    surface: int
    reversed: bool
    double: bool


@dataclass(frozen=True)
class Loop:
    next: int
    coedge: int


@dataclass(frozen=True)
class Coedge:
    next: int
    previous: int
    partner: int
    edge: int
    reversed: bool
    pcurve: int = -1


@dataclass(frozen=True)
class Edge:
    start: int
    end: int
    curve: int
    reversed: bool


@dataclass(frozen=True)
class Vertex:
    point: int


@dataclass(frozen=True)
class Transform:
    """p' = scale · (p · M) + t: M (3, 3) rows are the images of the axes."""

    rows: tuple[float, ...]
    translation: tuple[float, float, float]
    scale: float


class Model:
    """Decoded access to a file's records: `body(i)`, `face(i)`, …, `geometry(i)` → (class name, Cursor)."""

    def __init__(self, records: Records) -> None:
        self.records = records
        h = records.header
        self.version = h.version
        self.history = h.version >= 700
        self.spatial10 = h.version >= 1000 and not h.asm
        self.pattern = h.version >= 700

    def name(self, i: int) -> str:
        if not 0 <= i < len(self.records):
            raise fail(f"reference ${i} points outside the file's {len(self.records)} records")
        return self.records.names[i]

    def cursor(self, i: int, expect: str | None = None, pattern: bool = True) -> Cursor:
        """A cursor on record i past its common fields: attribute, history, and for topology and geometry
        (`pattern`) ACIS 10's integer and the pattern reference."""
        name = self.name(i)
        if expect is not None and name != expect and not name.endswith("-" + expect):
            raise fail(f"${i} should be a {expect}, it is a {name[:40]}")
        c = Cursor(self.records.tokens(i), f"{name[:40]} ${i}")
        c.ref()  # attributes
        if self.history:
            c.skip(1)
        if pattern and self.spatial10:
            c.skip(1)
        if pattern and self.pattern:
            c.ref()
        return c

    def body(self, i: int) -> Body:
        c = self.cursor(i, "body")
        return Body(c.ref_after_ints(), c.ref(), c.ref())

    def lump(self, i: int) -> Lump:
        c = self.cursor(i, "lump")
        return Lump(c.ref(), c.ref())

    def shell(self, i: int) -> Shell:
        c = self.cursor(i, "shell")
        nxt = c.ref()
        c.ref()  # subshell
        return Shell(nxt, c.ref())

    def face(self, i: int) -> Face:
        c = self.cursor(i, "face")
        nxt, loop = c.ref(), c.ref()
        c.ref(), c.ref()  # shell, subshell
        surface = c.ref()
        rev = c.flag("reversed", "forward")
        double = c.flag("double", "single")
        return Face(nxt, loop, surface, rev, double)

    def loop(self, i: int) -> Loop:
        c = self.cursor(i, "loop")
        return Loop(c.ref(), c.ref())

    def coedge(self, i: int) -> Coedge:
        c = self.cursor(i, "coedge")
        nxt, prev, partner, edge = c.ref(), c.ref(), c.ref(), c.ref()
        rev = c.flag("reversed", "forward")
        c.ref()  # its loop (or wire)
        pcurve = c.ref_after_ints() if c.peek() is not None else -1  # ASM 218+ puts an integer before it
        return Coedge(nxt, prev, partner, edge, rev, pcurve)

    def edge(self, i: int) -> Edge:
        c = self.cursor(i, "edge")
        start = c.ref()
        if self.version >= 500:
            c.num()
        end = c.ref()
        if self.version >= 500:
            c.num()
        c.ref()  # one coedge
        curve = c.ref()
        return Edge(start, end, curve, c.flag("reversed", "forward"))

    def vertex(self, i: int) -> Vertex:
        c = self.cursor(i, "vertex")
        c.ref()  # one edge
        return Vertex(c.ref_after_ints())

    def point(self, i: int) -> tuple[float, float, float]:
        return self.cursor(i, "point").vec()

    def transform(self, i: int) -> Transform:
        c = self.cursor(i, "transform", pattern=False)
        m = tuple(c.num() for _ in range(9))
        t = c.vec()
        return Transform(m, t, c.num())

    def geometry(self, i: int) -> tuple[str, Cursor]:
        """(class name, cursor at its own data) of a curve, surface or pcurve record."""
        return self.name(i), self.cursor(i)


__all__ = ["Body", "Coedge", "Cursor", "Edge", "Face", "Lump", "Loop", "Model", "Shell", "Transform", "Vertex",
           "CLOSE", "OPEN"]
