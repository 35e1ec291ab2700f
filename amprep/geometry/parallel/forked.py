"""Run one function in a forked child while the caller goes on with other work (two cores, one GIL): the child
inherits the arguments without copying, sends its result back pickled through a pipe, and a child that dies (a
crash in a C library) becomes an error instead of taking the caller down. Inline where there is no fork."""

from __future__ import annotations

import faulthandler
import gc
import multiprocessing as mp
import os
import pickle
import select
import signal
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from amprep.errors import AmprepError, ErrorCode, out_of_memory

T = TypeVar("T")


def cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def fork_available() -> bool:
    """True when os.fork exists, a second core can run the child and this is not a daemonic process (a Celery
    prefork child, whose parallelism is its siblings on the other cores)."""
    return hasattr(os, "fork") and cores() >= 2 and not mp.current_process().daemon


class Forked(Generic[T]):
    """fn(*args) started in a forked child (inline at result() when fork_available() is False or `fork` is False;
    with `isolate`, forked wherever os.fork exists, one core or a daemonic worker too: for a crash to end the child).
    The child must only read what it inherits: its changes to the caller's objects are lost. An AmprepError in the
    child is raised again by result(), a failed allocation as memory_limit; any other exception or a dead child
    raises `died` (code, message)."""

    def __init__(self, fn: Callable[..., T], *args: Any, died: tuple[ErrorCode, str] = (
            ErrorCode.INTERNAL_ERROR, "a helper process died"), fork: bool = True, isolate: bool = False) -> None:
        self._fn, self._args, self._died = fn, args, died
        self._pid = 0
        self._fd = -1
        self._value: tuple[str, Any] | None = None
        if fork and (fork_available() or (isolate and hasattr(os, "fork"))):
            self._start()

    @property
    def forked(self) -> bool:
        """True when the work runs in a child process."""
        return self._pid > 0

    def _start(self) -> None:
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: never returns into the caller's code
            code = 0
            # a collection would walk every object inherited from the parent, writing to their pages (copied on
            # write, thousands of page faults); the child is short-lived and exits without collecting
            gc.freeze()
            # a native crash here is the parent's to report (died → its code); the traceback dump that faulthandler
            # (pytest, a debug run) would print for the child's inherited stack is only noise
            faulthandler.disable()
            try:
                os.close(read)
                try:
                    out: tuple[str, Any] = ("ok", self._fn(*self._args))
                except AmprepError as exc:
                    out = ("amprep", (exc.code.value, exc.message))
                except BaseException as exc:  # noqa: BLE001 - below: reported to the parent
                    out = (("amprep", (ErrorCode.MEMORY_LIMIT.value, f"out of memory ({type(exc).__name__})"))
                           if out_of_memory(exc) else ("died", f"{type(exc).__name__}: {exc}"))
                data = pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL)
                with os.fdopen(write, "wb") as fh:
                    fh.write(data)
            except BaseException:  # noqa: BLE001 - a child must exit here whatever happens
                code = 1
            finally:
                os._exit(code)
        os.close(write)
        self._pid, self._fd = pid, read

    def ready(self, timeout: float = 0.0) -> bool:
        """True when result() will not wait (the child has finished, or nothing was forked)."""
        if self._fd < 0:
            return True
        return bool(select.select([self._fd], [], [], max(timeout, 0.0))[0])

    def result(self) -> T:
        """The function's value (waits for the child; computes it here when nothing was forked)."""
        if self._value is None:
            self._value = self._collect() if self._pid > 0 else self._inline()
        kind, value = self._value
        if kind == "ok":
            return value  # type: ignore[no-any-return]
        if kind == "amprep":
            raise AmprepError(ErrorCode(value[0]), value[1])
        raise AmprepError(self._died[0], f"{self._died[1]} ({value})")

    def _inline(self) -> tuple[str, Any]:
        return "ok", self._fn(*self._args)

    def _collect(self) -> tuple[str, Any]:
        chunks = []
        with os.fdopen(self._fd, "rb") as fh:
            while block := fh.read(1 << 20):
                chunks.append(block)
        self._fd = -1
        status = os.waitpid(self._pid, 0)[1]
        if not chunks:
            sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else 0
            return "died", f"killed by signal {sig}" if sig else f"exit status {os.waitstatus_to_exitcode(status)}"
        try:
            return pickle.loads(b"".join(chunks))  # type: ignore[no-any-return]
        except (pickle.UnpicklingError, EOFError):
            return "died", "a truncated result"

    def kill(self) -> None:
        """Stop the child now and reap it (its result is lost)."""
        if self._pid > 0 and self._fd >= 0:
            try:
                os.kill(self._pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self._reap()
            self._value = ("died", "killed")

    def _reap(self) -> None:
        """Close the pipe of a child whose result was never read and wait for it (no zombie left)."""
        if self._pid > 0 and self._fd >= 0:
            try:
                os.close(self._fd)
                os.waitpid(self._pid, 0)
            except OSError:
                pass
            self._fd = -1

    def __del__(self) -> None:  # a caller that never asked
        self._reap()
