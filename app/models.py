"""The API contract: job params per kind (unknown keys are an error) and what the API returns."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import AnyHttpUrl, BaseModel, ConfigDict, Field, model_validator

Kind = Literal["convert", "analyze", "refine"]
Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]


class _Params(BaseModel):
    model_config = ConfigDict(extra="forbid")

    callback_url: AnyHttpUrl | None = Field(
        None, description="POSTed the final job JSON when the job ends, signed in X-Amprep-Signature "
        "(sha256=HMAC-SHA256 of the body with the server's AMPREP_CALLBACK_SECRET)")
    reuse: bool = Field(True, description="Reuse a finished result of identical input bytes and params")


class _MeshingParams(_Params):
    tolerance: float = Field(0.1, gt=0, le=100, description="Max chord deviation from the exact surface, mm")
    relative: float | None = Field(None, gt=0, lt=1, description="Tolerance as a fraction of the bounding-box "
                                   "diagonal (replaces tolerance)")
    angular: float = Field(0.5, gt=0, le=1.57, description="Largest angle one segment of a curved edge turns "
                           "through, radians")
    min_size: float = Field(0.0, ge=0, description="Smallest triangle edge, mm (0: tolerance/10)")
    algorithm: Literal["delabella", "watson"] = Field("delabella", description="OCCT mesh algorithm")
    occt_edges: bool = Field(False, description="Discretise every B-rep edge as OCCT's BRepMesh does, at half the "
                             "tolerance and half the angle (more triangles); false: at 0.95× the tolerance where only "
                             "ruled faces meet (planes, cylinders, cones, extrusions)")
    own_large_faces: bool = Field(True, description="Mesh torus faces expected to need 20,000 triangles or more "
                                  "ourselves from curvature-sized points (faster than OCCT, fewer triangles); false "
                                  "leaves every face to OCCT's BRepMesh")


class ConvertParams(_MeshingParams):
    """Params of a convert job: CAD or STL in, closed STL or 3MF out."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"tolerance": 0.05, "format": "stl"}]})

    format: Literal["stl", "3mf"] = Field("stl", description="Output format")
    ascii: bool = Field(False, description="ASCII STL instead of binary")


class _PrintParams(_MeshingParams):
    """Layer thickness and build direction, for the cusp height."""

    layer: float = Field(0.2, gt=0, le=10, description="Layer thickness, mm (cusp height)")
    build_dir: tuple[float, float, float] = Field((0.0, 0.0, 1.0), description="Build direction")

    @model_validator(mode="after")
    def _nonzero_direction(self) -> _PrintParams:
        if sum(c * c for c in self.build_dir) == 0:
            raise ValueError("build_dir must not be the zero vector")
        return self


class AnalyzeParams(_PrintParams):
    """Params of an analyze job: the error report of a CAD part's tessellation, or of an STL."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"layer": 0.2, "build_dir": [0, 0, 1]}]})

    sample_order: int = Field(6, ge=1, le=30, description="Chordal sampling order inside each triangle")
    cloud_density: float | None = Field(None, gt=0, le=10000, description="Points per mm² for the bounding-box cusp "
                                        "method (default (4/layer)², at most 2 M points)")
    bounding_box: bool = Field(True, description="Also run the thesis's bounding-box cusp-height method")


class RefineParams(_PrintParams):
    """Params of a refine job: densify the curved faces whose error is too high (SMA, or its baseline VTA) and
    compare with uniform re-tessellations. With an `stl` part, that STL is refined and returned in its own frame."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{"method": "sma", "max_chordal": 0.02}]})

    tolerance: float = Field(0.2, gt=0, le=100, description="Tolerance of the first tessellation when no STL is given")
    method: Literal["sma", "vta", "adaptive"] = Field("sma", description="sma (the thesis), vta (its baseline) "
                                                      "or adaptive (error-driven edge bisection)")
    faces: list[int] | None = Field(None, description="CAD face ids to refine (else chosen by the thresholds; "
                                    "with no threshold, every curved face)")
    max_chordal: float | None = Field(None, gt=0, description="Refine curved faces whose mean chordal error exceeds this, mm")
    max_cusp: float | None = Field(None, gt=0, description="Refine curved faces whose mean cusp height exceeds this, mm")
    max_cylindricity: float | None = Field(None, gt=0, description="Refine cylinders whose zone exceeds this, mm")
    ratios: str = Field("3:4:3,3:4:3", pattern=r"^\d+(\.\d+)?:\d+(\.\d+)?:\d+(\.\d+)?,\d+(\.\d+)?:\d+(\.\d+)?:\d+(\.\d+)?$",
                        description="SMA spoke ratio a:b:c and edge ratio p:q:p")
    iterations: int = Field(1, ge=1, le=50, description="VTA iterations")
    target: float | None = Field(None, gt=0, description="adaptive: chordal error every refined triangle must reach, "
                                 "mm (default: a tenth of the chosen faces' worst)")
    compare: bool = Field(True, description="Add uniform re-tessellations and the other method to the report")
    max_triangles: int = Field(10_000_000, ge=1, le=50_000_000, description="Refuse (output_too_large) a "
                               "refinement predicted to output more triangles than this")
    format: Literal["stl", "3mf"] = Field("stl", description="Output format")
    ascii: bool = Field(False, description="ASCII STL instead of binary")


PARAMS_MODEL: dict[str, type[_Params]] = {"convert": ConvertParams, "analyze": AnalyzeParams, "refine": RefineParams}


class ErrorInfo(BaseModel):
    code: str = Field(description="Stable machine-readable code", examples=["unreadable_cad"])
    message: str


class Artifact(BaseModel):
    name: str = Field(examples=["part.stl"])
    media_type: str = Field(examples=["model/stl"])
    size: int
    sha256: str
    url: str = Field(examples=["/v1/jobs/0192f0a1b2c3d4e5f6a7b8c9d0e1f2a3/artifacts/part.stl"])


class JobPublic(BaseModel):
    """A job as clients see it."""

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "id": "0192f0a1b2c3d4e5f6a7b8c9", "kind": "convert", "status": "succeeded", "progress": 1.0, "stage": "done",
        "error": None, "params": {"tolerance": 0.1}, "input": {"file": {"name": "part.step", "size": 84211,
        "sha256": "…", "format": "step"}}, "artifacts": [], "result": None, "provenance": {"amprep": "0.2.0"},
        "reused_from": None, "idempotency_key": None, "attempts": 1, "worker": "host:4242",
        "created_at": "2026-11-22T10:00:00.000Z", "started_at": "2026-11-22T10:00:00.120Z",
        "finished_at": "2026-11-22T10:00:01.870Z"}]})

    id: str
    kind: Kind
    status: Status
    progress: float = Field(ge=0, le=1)
    stage: str
    error: ErrorInfo | None
    params: dict[str, Any] = Field(description="All params after defaults")
    input: dict[str, Any] = Field(description="Uploaded files: name, size, sha256, format")
    artifacts: list[Artifact]
    result: dict[str, Any] | None = Field(description="Summary of the result (the full report is an artifact)")
    provenance: dict[str, Any] = Field(description="amprep, OCCT and cadquery versions and params that made it")
    reused_from: str | None = Field(description="The earlier job whose result this one reuses, if any")
    idempotency_key: str | None
    attempts: int
    worker: str | None
    created_at: str
    started_at: str | None
    finished_at: str | None


class JobList(BaseModel):
    """One page of jobs, newest first."""

    jobs: list[JobPublic]
    next_cursor: str | None = Field(description="Pass as ?cursor= for the next page; null on the last page")


class Problem(BaseModel):
    """RFC 9457 problem details with a stable `code`."""

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "type": "about:blank", "title": "Unprocessable Entity", "status": 422, "code": "invalid_request",
        "detail": "params.bogus: Extra inputs are not permitted", "instance": "/v1/jobs"}]})

    type: str = Field("about:blank")
    title: str
    status: int
    detail: str
    code: str = Field(examples=["invalid_request"])
    instance: str | None = None
    errors: list[dict[str, Any]] | None = None
    job_id: str | None = None
