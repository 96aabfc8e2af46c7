"""Risky work in a child process with a timeout: the one way dynatex runs it.

Reading a corrupt database (HDF5 may segfault or loop), decoding a video (a decoder may crash) and
proving an OpenCL device (a driver may crash or hang) run in a child, so that a crash, a hang or
an out-of-memory kill ends the child, never the caller. :func:`call` runs ``module:function`` in
a fresh interpreter (``python -m dynatex.child``: safe in a process with threads and on every
platform, unlike ``fork``) and returns an :class:`Outcome`: how the child ended, what it printed,
its peak memory, and what the function returned or raised.

- The child runs in a session of its own and ignores Ctrl-C: stopping is the parent's decision.
  Ctrl-C and SIGTERM are held back in the parent while the child starts (an interrupt there would
  leave a child no one waits for) and take effect once it runs; when they interrupt the wait, or
  the child overruns ``timeout``, the parent kills the child and everything it started.
- A child ends with its parent, however the parent ends (killed outright included): its stdin is
  a pipe the parent never writes to, and when it closes the child kills itself and what it started.
- Every wait has a bound: a child that a kill cannot end (stuck in the kernel) is left after
  :data:`REAP_S` seconds rather than hanging the caller.
- What the child prints goes to unlinked temporary files, not pipes, so a child (or a compiler
  it started) that prints much or keeps the pipes open cannot stall the parent.

The function's arguments and its return value travel as JSON (lists come back for tuples). An
error it raises comes back as its class name and a one-line message (:attr:`Outcome.raised`),
exit status 1; a ``MemoryError``, exit status :data:`MEMORY_STATUS`.

This module imports nothing above :mod:`dynatex.errors`, so the tile database and the player use
it without pulling in anything heavy. ``DYNATEX_PYTHON`` names the interpreter for the child
where ``sys.executable`` is an application embedding Python rather than Python itself.

Examples
--------
>>> outcome = call("os.path:join", "a", "b", timeout=60)
>>> outcome.status, outcome.value
(0, 'a/b')
>>> call("math:sqrt", -1.0, timeout=60).raised
('ValueError', 'math domain error')
"""

from __future__ import annotations

import importlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import ChildStartError

#: the child's exit status when its work raised MemoryError
MEMORY_STATUS = 3
#: seconds to wait for a child after killing it before leaving it
REAP_S = 10.0
#: what a user sends to stop a run: held back while a child starts, ignored by the child
STOPS = (signal.SIGINT, signal.SIGTERM)
#: set by :func:`call` in the child's environment: its stdin is the lifeline (:func:`end_with_parent`)
LIFELINE = "DYNATEX_CHILD_LIFELINE"
_VALUE, _RAISED = "dynatex-child-value\t", "dynatex-child-raised\t"

__all__ = ["MEMORY_STATUS", "Outcome", "call", "ignore_stops", "interpreter"]


@dataclass
class Outcome:
    """How a child ended and what it left."""

    #: exit status (0 ok, 1 the function raised, :data:`MEMORY_STATUS`); negative: the signal that
    #: ended it; None: it overran ``timeout`` and was killed
    status: int | None
    timeout: float
    seconds: float
    peak_bytes: int = 0  # the child's peak resident memory (0 where the platform does not say)
    out: str = ""  # what it printed on stdout (the protocol's last line aside)
    err: str = ""  # what it printed on stderr
    value: Any = None  # what the function returned (status 0)
    raised: tuple[str, str] | None = None  # (class name, one-line message) of what it raised

    @property
    def ok(self) -> bool:
        return self.status == 0

    @property
    def timed_out(self) -> bool:
        return self.status is None

    def describe(self) -> str:
        """How the child ended, in a few words: ``"crashed (signal 11)"``, ``"did not finish within 30 s"``."""
        if self.status is None:
            return f"did not finish within {self.timeout:.0f} s"
        if self.status < 0:
            return f"crashed (signal {-self.status})"
        if self.status == MEMORY_STATUS:
            return f"ran out of memory (peak resident memory {self.peak_bytes / 2**20:.0f} MiB)"
        if self.raised is not None:
            return f"failed: {self.raised[0]}: {self.raised[1]}"
        return f"exited with status {self.status}"


def interpreter() -> str | None:
    """The Python interpreter a child runs in (``DYNATEX_PYTHON``, else ``sys.executable``), or None
    where that is no Python (an application embedding Python: starting it could start the app)."""
    python = os.environ.get("DYNATEX_PYTHON") or sys.executable
    return python if python and "python" in Path(python).name.lower() else None


def call(target: str, *args: Any, timeout: float) -> Outcome:
    """Run ``target`` (``"package.module:function"``) with JSON-able ``args`` in a child process and
    wait at most ``timeout`` seconds; a :class:`~dynatex.errors.ChildStartError` when no child
    can be started (no interpreter, no process)."""
    python = interpreter()
    if python is None:
        python = os.environ.get("DYNATEX_PYTHON") or sys.executable
        raise ChildStartError(
            f"cannot start a child process: {python!r} is not a Python interpreter (set DYNATEX_PYTHON to one)"
        )
    env = dict(os.environ)
    env.pop("PYTHONFAULTHANDLER", None)  # any value turns it on: its dump is not our protocol
    env[LIFELINE] = "1"
    cmd = [python, "-m", "dynatex.child", target, json.dumps(list(args))]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.monotonic()
        proc = _start(cmd, out, err, env)
        try:
            status, peak = _wait(proc, timeout)
        except BaseException:  # an interrupt: the child must not outlive the wait
            _kill(proc)
            raise
        finally:
            proc.stdin.close()
        seconds = time.monotonic() - start
        text, errors = _read(out), _read(err)
    outcome = Outcome(status, timeout, seconds, peak, err=errors)
    lines = []
    for line in text.splitlines():
        if line.startswith((_VALUE, _RAISED)) and status in (0, 1):
            word, _, data = line.partition("\t")
            if word + "\t" == _VALUE:
                outcome.value = json.loads(data)
            else:
                outcome.raised = tuple(json.loads(data))  # type: ignore[assignment]
        else:
            lines.append(line)
    outcome.out = "\n".join(lines)
    return outcome


def _start(cmd: list[str], out, err, env: dict) -> subprocess.Popen:
    """The child, started with Ctrl-C and SIGTERM held back (they take effect once ``Popen`` has
    returned, so the caller always holds the child it must kill)."""
    hold = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOPS) if hold else None
    try:
        return subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,  # the lifeline (end_with_parent); never written to
            stdout=out,
            stderr=err,
            env=env,
            start_new_session=os.name == "posix",
        )
    except OSError as exc:
        raise ChildStartError(f"cannot start a child process: {exc}") from None
    finally:
        if hold:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _wait(proc: subprocess.Popen, timeout: float) -> tuple[int | None, int]:
    """The child's exit status (None: killed after ``timeout``) and peak resident bytes."""
    if not hasattr(os, "wait4"):
        try:
            return proc.wait(timeout), 0
        except subprocess.TimeoutExpired:
            _kill(proc)
            return None, 0
    deadline = time.monotonic() + timeout
    delay = 0.001
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return proc.returncode, int(usage.ru_maxrss) * (1 if sys.platform == "darwin" else 1024)
        if time.monotonic() >= deadline:
            _kill(proc)
            return None, 0
        time.sleep(delay)
        delay = min(delay * 2, 0.05)


def _kill(proc: subprocess.Popen) -> None:
    """Kill the child and whatever it started (a compiler), and reap it (at most :data:`REAP_S` s)."""
    try:
        if os.name == "posix":
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.kill()
    except OSError:  # already gone
        pass
    try:
        proc.wait(REAP_S)
    except subprocess.TimeoutExpired:  # stuck in the kernel: leave it rather than hang
        pass


def _read(f) -> str:
    f.seek(0)
    return f.read().decode("utf-8", errors="replace")


# -- the child's side ---------------------------------------------------------------------
def ignore_stops() -> None:
    """In a child: ignore Ctrl-C (the parent kills the child when it stops) and take the signals
    the parent held back while starting it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPS)


def end_with_parent() -> None:
    """In a child that :func:`call` started: when the parent is gone (the lifeline on stdin
    closes, however the parent ended), kill this child's session (itself and what it started;
    only itself where it leads no session of its own)."""

    def watch() -> None:
        try:
            while os.read(0, 4096):  # the raw descriptor: a daemon thread in sys.stdin's lock aborts exit
                pass
        except OSError:
            return
        if os.name == "posix" and os.getsid(0) == os.getpid():
            os.killpg(0, signal.SIGKILL)
        os._exit(1)

    threading.Thread(target=watch, name="dynatex-lifeline", daemon=True).start()


def _one_line(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__


def _main(argv: list[str]) -> int:
    """``python -m dynatex.child MODULE:FUNCTION JSON_ARGS``: print what the function returns (or
    raises) as the last line of stdout; exit 0, 1 when it raised, :data:`MEMORY_STATUS` on MemoryError."""
    if len(argv) != 2 or ":" not in argv[0]:
        print("usage: python -m dynatex.child MODULE:FUNCTION JSON_ARGS  (run by dynatex.child.call)", file=sys.stderr)
        return 2
    ignore_stops()
    if os.environ.pop(LIFELINE, None) == "1":  # not when run by hand or by another program
        end_with_parent()
    module, _, function = argv[0].partition(":")
    try:
        value = getattr(importlib.import_module(module), function)(*json.loads(argv[1]))
        line = _VALUE + json.dumps(value)
    except MemoryError:
        return MEMORY_STATUS
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which decides
        print(f"{type(exc).__name__}: {_one_line(exc)}", file=sys.stderr)
        line = _RAISED + json.dumps([type(exc).__name__, _one_line(exc)])
    sys.stdout.flush()
    print(line, flush=True)
    return 1 if line.startswith(_RAISED) else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
