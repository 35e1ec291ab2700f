"""Errors with a stable code: the library raises AmprepError, every edge maps its code once."""

from __future__ import annotations

from enum import StrEnum


class ErrorCode(StrEnum):
    """Stable, machine-readable error codes (part of the public API: never renamed)."""

    UNSUPPORTED_FORMAT = "unsupported_format"
    UNREADABLE_CAD = "unreadable_cad"
    UNREADABLE_MESH = "unreadable_mesh"
    EMPTY_MODEL = "empty_model"
    INVALID_PARAMETER = "invalid_parameter"
    MESHING_FAILED = "meshing_failed"
    WRITE_FAILED = "write_failed"
    CANCELLED = "cancelled"
    NOT_IMPLEMENTED = "not_implemented"
    STL_MISMATCH = "stl_mismatch"
    OUTPUT_TOO_LARGE = "output_too_large"
    MEMORY_LIMIT = "memory_limit"
    # Raised by the service around the library (jobs and HTTP), listed here so there is one enum of codes.
    WORKER_CRASHED = "worker_crashed"
    TIME_LIMIT = "time_limit"
    INTERNAL_ERROR = "internal_error"
    INVALID_REQUEST = "invalid_request"
    NOT_FOUND = "not_found"
    UNAUTHORIZED = "unauthorized"
    UPLOAD_TOO_LARGE = "upload_too_large"
    NOT_ACCEPTABLE = "not_acceptable"
    CONFLICT = "conflict"
    UNAVAILABLE = "unavailable"
    CALLBACK_REFUSED = "callback_refused"


class AmprepError(Exception):
    """An error the user can act on: `code` is stable, `message` is one line for a person."""

    def __init__(self, code: ErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message

    def __str__(self) -> str:
        return f"{self.code.value}: {self.message}"


def out_of_memory(exc: BaseException) -> bool:
    """True for a failed allocation: Python's MemoryError or OCCT's Standard_OutOfMemory (past the job's memory
    limit, amprep/memory.py)."""
    return isinstance(exc, MemoryError) or "OutOfMemory" in type(exc).__name__


def is_occt_failure(exc: BaseException) -> bool:
    """True for an exception OCCT raised through OCP (its Standard_Failure family, classes of OCP's modules, or
    pybind11's RuntimeError for another C++ exception): what the library turns into a stable code. Anything else
    (a job's time limit or a cancellation arriving while OCCT ran, an allocation past the memory limit, a bug) must
    pass through unchanged."""
    if out_of_memory(exc):
        return False
    return type(exc).__module__.startswith("OCP") or type(exc) is RuntimeError
