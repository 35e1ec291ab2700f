"""The API contract: job params per kind, generated from amprep.jobs.params (unknown keys are an error), and what
the API returns."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import AnyHttpUrl, BaseModel, ConfigDict, Field, create_model

from amprep.jobs.params import KINDS, JobKind, Param

Kind = Literal["convert", "analyze", "refine"]
Status = Literal["queued", "running", "succeeded", "failed", "cancelled"]

EXAMPLES = {"convert": {"tolerance": 0.05, "format": "stl"}, "analyze": {"layer": 0.2, "build_dir": [0, 0, 1]},
            "refine": {"method": "sma", "max_chordal": 0.02}}
_TYPES: dict[str, Any] = {"float": float, "int": int, "bool": bool, "text": str, "url": AnyHttpUrl,
                          "vector3": tuple[float, float, float], "ids": list[int]}


def _field(p: Param) -> tuple[Any, Any]:
    """(annotation, Field) of one parameter: its type (a Literal of its choices), default, bounds and help."""
    annotation: Any = Literal[p.choices] if p.choices else _TYPES[p.type]  # type: ignore[valid-type]
    if p.optional:
        annotation = annotation | None
    extra = {"x-unit": p.unit} if p.unit else None
    return annotation, Field(p.default, gt=p.gt, ge=p.ge, lt=p.lt, le=p.le, pattern=p.pattern,
                             description=p.describe(), json_schema_extra=extra)


def _params_model(kind: JobKind) -> type[BaseModel]:
    """The API model of a kind's params, generated from jobs.params (unknown keys and non-finite numbers refused)."""
    config = ConfigDict(extra="forbid", allow_inf_nan=False, json_schema_extra={"examples": [EXAMPLES[kind.name]]})
    model = create_model(f"{kind.name.capitalize()}Params", __config__=config,
                         **{p.name: _field(p) for p in kind.params})  # type: ignore[call-overload]
    model.__doc__ = f"Params of a {kind.name} job: {kind.help}."
    return model


PARAMS_MODEL: dict[str, type[BaseModel]] = {name: _params_model(kind) for name, kind in KINDS.items()}
assert set(PARAMS_MODEL) == set(Kind.__args__)  # type: ignore[attr-defined]


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


class ParamInfo(BaseModel):
    """One job parameter as its definition gives it (what the dashboard builds its form from)."""

    name: str
    type: Literal["float", "int", "bool", "choice", "vector3", "ids", "text", "url"]
    default: Any = Field(description="The default value (null: none)")
    help: str
    description: str = Field(description="The help with its unit and bounds, as the API docs and the CLI show it")
    unit: str
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: list[str]
    pattern: str | None = None
    optional: bool = Field(description="null is allowed")
    service_only: bool = Field(description="a key of the API only (no CLI option)")


class KindInfo(BaseModel):
    """A job kind: what it does, what it takes and its parameters."""

    name: Kind
    help: str
    input_help: str
    takes_stl: bool = Field(description="the `stl` part is accepted beside `file`")
    artifacts: list[str] = Field(description="its main artifacts, in order of preference")
    params: list[ParamInfo]

    @classmethod
    def of(cls, kind: JobKind) -> KindInfo:
        params = [ParamInfo(name=p.name, type=p.type, default=list(p.default) if isinstance(p.default, tuple)  # type: ignore[arg-type]
                            else p.default, help=p.help, description=p.describe(), unit=p.unit, gt=p.gt, ge=p.ge,
                            lt=p.lt, le=p.le, choices=list(p.choices), pattern=p.pattern, optional=p.optional,
                            service_only=p.service_only) for p in kind.params]
        return cls(name=kind.name, help=kind.help, input_help=kind.input_help, takes_stl=kind.takes_stl,  # type: ignore[arg-type]
                   artifacts=list(kind.artifacts), params=params)
