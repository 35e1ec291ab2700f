"""Structured logs: one JSON object per line, with the job id of the job being served or run on every line."""

from __future__ import annotations

import contextvars
import json
import logging
import sys
import time

job_id_var: contextvars.ContextVar[str | None] = contextvars.ContextVar("amprep_job_id", default=None)


def _celery_task_id(record: logging.LogRecord) -> str | None:
    """Celery's own lines about a task ("received", "succeeded") carry its id, which is the job id, in args."""
    args = record.args
    return args.get("id") if isinstance(args, dict) else None  # type: ignore[return-value]


class JsonFormatter(logging.Formatter):
    """{"ts", "level", "logger", "msg", "job_id", ...extra} per record."""

    def format(self, record: logging.LogRecord) -> str:
        out = {
            "ts": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created)) + f".{int(record.msecs):03d}Z",
            "level": record.levelname.lower(),
            "logger": record.name,
            "msg": record.getMessage(),
            "job_id": getattr(record, "job_id", None) or job_id_var.get() or _celery_task_id(record),
        }
        for key in ("kind", "status", "method", "path", "code", "duration_ms", "pid"):
            if hasattr(record, key):
                out[key] = getattr(record, key)
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        return json.dumps(out, default=str)


def setup_logging(level: str = "INFO") -> None:
    """Route the root logger (and Celery's and uvicorn's) to JSON lines on stderr."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(JsonFormatter())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    for name in ("uvicorn", "uvicorn.error", "uvicorn.access", "celery"):
        lg = logging.getLogger(name)
        lg.handlers[:] = []
        lg.propagate = True
