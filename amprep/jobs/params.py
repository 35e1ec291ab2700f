"""One definition of every job kind and its parameters: the API's models, the CLI's options, the runner, the tasks,
the client and the OpenAPI document are all generated from KINDS; `check` is the one place bounds are enforced.

A parameter's name is the API's key (snake_case) and the CLI's option (kebab-case: `min_size` ↔ `--min-size`, a
bool `compare` ↔ `--compare/--no-compare`), with the same default and bounds. Service-only keys (`callback_url`,
`reuse`) are API keys only. Values fill the geometry library's parameter dataclasses by field name (`build`).
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any

from amprep.errors import AmprepError, ErrorCode
from amprep.geometry.core.limits import DEFAULT_MAX_TRIANGLES, MAX_TOLERANCE, MAX_TRIANGLES_CAP, MIN_TOLERANCE


@dataclass(frozen=True)
class Param:
    """One job parameter: `type` float | int | bool | choice | vector3 | ids | text | url; bounds gt/ge/lt/le (numbers),
    `choices` (choice), `pattern` (text), `optional`: null allowed (the default is then null unless given)."""

    name: str
    type: str
    default: Any
    help: str
    unit: str = ""
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] = ()
    pattern: str | None = None
    optional: bool = False
    service_only: bool = False

    @property
    def option(self) -> str:
        """The CLI option: --kebab-case."""
        return "--" + self.name.replace("_", "-")

    def bounds_text(self) -> str:
        """The bounds in words, e.g. '> 0, ≤ 100'."""
        parts = [f"{op} {_num(v)}" for op, v in (("> ", self.gt), ("≥ ", self.ge), ("< ", self.lt), ("≤ ", self.le))
                 if v is not None]
        return ", ".join(p.replace("  ", " ") for p in parts)

    def describe(self) -> str:
        """The help text with its unit and bounds, as the API, the CLI and the dashboard show it."""
        extra = ", ".join(x for x in (self.unit, self.bounds_text()) if x)
        return f"{self.help} ({extra})" if extra else self.help


def _num(v: float) -> str:
    return f"{int(v):,}" if float(v).is_integer() and abs(v) >= 1000 else f"{v:g}"


@dataclass(frozen=True)
class JobKind:
    """A job kind: its parameters, its main artifacts (in order of preference), its Celery queue and whether it takes
    a user's STL beside its input."""

    name: str
    help: str
    params: tuple[Param, ...]
    artifacts: tuple[str, ...]
    queue: str
    takes_stl: bool
    input_help: str

    def param(self, name: str) -> Param:
        return next(p for p in self.params if p.name == name)

    @property
    def task(self) -> str:
        """The Celery task name the API sends this kind's jobs to."""
        return f"amprep.{self.name}"


def _meshing(tolerance: float, help_tolerance: str) -> tuple[Param, ...]:
    return (
        Param("tolerance", "float", tolerance, help_tolerance, "mm", ge=MIN_TOLERANCE, le=MAX_TOLERANCE),
        Param("relative", "float", None, "Tolerance as a fraction of the bounding-box diagonal (replaces tolerance; "
              f"the result must be at least {MIN_TOLERANCE:g} mm)", ge=1e-6, lt=1, optional=True),
        Param("angular", "float", 0.5, "Largest angle one segment of a curved edge turns through", "rad", gt=0, le=1.57),
        Param("min_size", "float", 0.0, "Shortest edge the meshers aim for. occt: BRepMesh's smallest triangle edge "
              "(0: tolerance/10); quality: the size it cuts boundary edges to, to follow a narrow face's width, is "
              "at least this (0: the tolerance), so thin walls and strips get fewer, thinner triangles. The chord "
              "tolerance still cuts finer wherever it must", "mm", ge=0, le=100),
        Param("algorithm", "choice", "delabella", "OCCT mesh algorithm (mesher occt)", choices=("delabella", "watson")),
        Param("mesher", "choice", "occt", "occt: OCCT's BRepMesh, mended by ours where it breaks the tolerance; "
              "quality: every face by ours (seed 000: planes by constrained Delaunay to a 30° minimum angle, curved "
              "faces from a (u,v) grid cut near square on the surface, boundary segments graded to the faces' "
              "width): triangles a finite-element or smoothing user would accept, 2-4× as many at a coarse "
              "tolerance (docs/meshing.md)", choices=("occt", "quality")),
        Param("occt_edges", "bool", False, "Mesher occt: discretise every B-rep edge as OCCT's BRepMesh does, at half "
              "the tolerance and half the angle (more triangles); off: at 0.95× the tolerance where only ruled faces "
              "meet (planes, cylinders, cones, extrusions)"),
        Param("max_triangles", "int", DEFAULT_MAX_TRIANGLES, "Refuse (output_too_large) a job whose output is "
              "predicted to have more triangles than this: for CAD, estimated from the B-rep before meshing (the "
              "quality mesher's from its edges and the faces' curvature, before any face is meshed) and kept as "
              "the mesh is made; for refine, the refinement's own size", ge=1, le=MAX_TRIANGLES_CAP),
        Param("own_large_faces", "bool", True, "Mesher occt: mesh torus faces expected to need 20,000 triangles or "
              "more ourselves from curvature-sized points (faster than OCCT, fewer triangles); off leaves every face "
              "to OCCT's BRepMesh"),
    )


_PRINT = (
    Param("layer", "float", 0.2, "Layer thickness (cusp height)", "mm", gt=0, le=10),
    Param("build_dir", "vector3", (0.0, 0.0, 1.0), "Build direction x,y,z (not the zero vector)"),
)
_OUTPUT = (
    Param("format", "choice", "stl", "Output format (the CLI takes it from -o's extension when not given)",
          choices=("stl", "3mf")),
    Param("ascii", "bool", False, "ASCII STL instead of binary"),
)
_SERVICE = (
    Param("callback_url", "url", None, "POSTed the final job JSON when the job ends, signed in X-Amprep-Signature "
          "(sha256=HMAC-SHA256 of the body with the server's AMPREP_CALLBACK_SECRET)", optional=True, service_only=True),
    Param("reuse", "bool", True, "Reuse a finished result of identical input bytes and params", service_only=True),
)
_RATIO = r"\d+(\.\d+)?:\d+(\.\d+)?:\d+(\.\d+)?"

KINDS: dict[str, JobKind] = {k.name: k for k in (
    JobKind("convert", "CAD or STL in, closed STL or 3MF out within a chord tolerance",
            _meshing(0.1, "Max chord deviation from the exact surface") + _OUTPUT + _SERVICE,
            ("part.stl", "part.3mf"), "quick", False, "STEP, IGES, BREP, ACIS (SAT, SAB, DXF) or STL (recognised from its bytes)"),
    JobKind("analyze", "The error report: mesh checks, defects, chordal error, cusp height, cylindricity, regularity",
            _meshing(0.1, "Tessellation tolerance for CAD input") + _PRINT + (
                Param("sample_order", "int", 6, "Chordal sampling order inside each triangle (6: 28 points)", ge=1, le=30),
                Param("cloud_density", "float", None, "Points per mm² for the bounding-box cusp method (default "
                      "(4/layer)², at most 2 M points)", "1/mm²", gt=0, le=10000, optional=True),
                Param("bounding_box", "bool", True, "Also run the thesis's bounding-box cusp-height method"),
            ) + _SERVICE,
            ("report.json",), "quick", True, "STEP, IGES, BREP or ACIS (SAT, SAB, DXF) (tessellated as convert does), or an STL"),
    JobKind("refine", "Densify the curved faces whose error is too high (SMA, VTA or adaptive), keeping the mesh closed; "
            "or refine an STL alone (butterfly)",
            _meshing(0.2, "Tolerance of the first tessellation when no STL is given") + _PRINT + (
                Param("method", "choice", "sma", "sma (the thesis), vta (its baseline), adaptive (error-driven edge "
                      "bisection), or butterfly (an STL alone, no CAD: the modified Butterfly limit surface)",
                      choices=("sma", "vta", "adaptive", "butterfly")),
                Param("faces", "ids", None, "CAD face ids to refine, e.g. 3,7 (else chosen by the thresholds; with no "
                      "threshold, every curved face)", optional=True),
                Param("max_chordal", "float", None, "Refine curved faces whose mean chordal error exceeds this", "mm",
                      gt=0, optional=True),
                Param("max_cusp", "float", None, "Refine curved faces whose mean cusp height exceeds this", "mm", gt=0,
                      optional=True),
                Param("max_cylindricity", "float", None, "Refine cylinders whose cylindricity zone exceeds this", "mm",
                      gt=0, optional=True),
                Param("ratios", "text", "3:4:3,3:4:3", "SMA spoke ratio a:b:c and edge ratio p:q:p",
                      pattern=f"^{_RATIO},{_RATIO}$"),
                Param("iterations", "int", 1, "VTA iterations", ge=1, le=50),
                Param("target", "float", None, "adaptive: chordal error every refined triangle must reach (default: a "
                      "tenth of the chosen faces' worst)", "mm", gt=0, optional=True),
                Param("compare", "bool", True, "Add uniform re-tessellations and the other method to the report"),
                Param("levels", "int", 1, "butterfly: levels of 1-to-4 splitting (each ×4 the triangles); 0: as many "
                      "as max_triangles allows", ge=0, le=6),
                Param("max_edge", "float", None, "butterfly: instead of levels, split edges (longest first, new nodes "
                      "on the limit surface) until none is longer than this", "mm", gt=0, le=1000, optional=True),
                Param("feature_angle", "float", 30.0, "butterfly: dihedral angle over which an edge is a sharp feature "
                      "curve, kept sharp", "deg", gt=0, lt=180),
            ) + _OUTPUT + _SERVICE,
            ("refined.stl", "refined.3mf"), "heavy", True, "STEP, IGES, BREP or ACIS (SAT, SAB, DXF) (with the STL to refine as `stl`), or "
            "an STL alone with method butterfly"),
)}


def _bad(name: str, why: str) -> AmprepError:
    return AmprepError(ErrorCode.INVALID_PARAMETER, f"{name}: {why}")


def _number(p: Param, value: Any) -> float | int:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _bad(p.name, f"expected a number, got {value!r}")
    if p.type == "int" and not float(value).is_integer():
        raise _bad(p.name, f"expected an integer, got {value!r}")
    if not math.isfinite(value):
        raise _bad(p.name, f"expected a finite number, got {value!r}")
    for ok, op, bound in ((lambda v, b: v > b, ">", p.gt), (lambda v, b: v >= b, "≥", p.ge),
                          (lambda v, b: v < b, "<", p.lt), (lambda v, b: v <= b, "≤", p.le)):
        if bound is not None and not ok(value, bound):
            raise _bad(p.name, f"must be {op} {_num(bound)}, got {value!r}")
    return int(value) if p.type == "int" else float(value)


def _value(p: Param, value: Any) -> Any:
    """One value checked against its parameter and normalised (tuples for vectors and ids)."""
    if value is None:
        if p.optional:
            return None
        raise _bad(p.name, "must not be null")
    if p.type in ("float", "int"):
        return _number(p, value)
    if p.type == "bool":
        if not isinstance(value, bool):
            raise _bad(p.name, f"expected true or false, got {value!r}")
        return value
    if p.type == "choice":
        if value not in p.choices:
            raise _bad(p.name, f"must be one of {', '.join(p.choices)}, got {value!r}")
        return value
    if p.type == "vector3":
        if not isinstance(value, list | tuple) or len(value) != 3:
            raise _bad(p.name, f"expected three numbers x,y,z, got {value!r}")
        vec = tuple(_number(dataclasses.replace(p, type="float"), v) for v in value)
        if not any(vec):
            raise _bad(p.name, "must not be the zero vector")
        return vec
    if p.type == "ids":
        if not isinstance(value, list | tuple) or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            raise _bad(p.name, f"expected a list of face ids, got {value!r}")
        return tuple(int(v) for v in value)
    if not isinstance(value, str):
        raise _bad(p.name, f"expected text, got {value!r}")
    if p.pattern is not None and not re.fullmatch(p.pattern, value):
        raise _bad(p.name, f"'{value}' is not of the form {p.default}")
    return value


def check(kind: str, values: dict[str, Any], service: bool = False) -> dict[str, Any]:
    """Every parameter of `kind`, defaults filled in, checked against its bounds and normalised; unknown keys (and
    service-only keys unless `service`) are invalid_parameter."""
    if kind not in KINDS:
        raise AmprepError(ErrorCode.INVALID_PARAMETER, f"unknown job kind '{kind}'")
    spec = KINDS[kind]
    known = {p.name for p in spec.params if service or not p.service_only}
    unknown = sorted(set(values) - known)
    if unknown:
        raise _bad(unknown[0], f"not a parameter of {kind} (known: {', '.join(sorted(known))})")
    return {p.name: _value(p, values.get(p.name, p.default)) for p in spec.params if p.name in known}


def build(cls: type, values: dict[str, Any]) -> Any:
    """An instance of a geometry parameter dataclass from checked values: the fields it shares with them by name."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in values.items() if k in names})


def parse_cli_value(p: Param, text: str) -> Any:
    """A CLI string as the parameter's JSON type: x,y,z for vectors, 3,7 for ids, numbers as numbers."""
    try:
        if p.type == "vector3":
            return [float(x) for x in text.split(",")]
        if p.type == "ids":
            return [int(x) for x in text.split(",") if x.strip()]
        if p.type == "int":
            return int(text)
        if p.type == "float":
            return float(text)
    except ValueError:
        raise _bad(p.name, f"cannot read '{text}' as {p.type}") from None
    return text
