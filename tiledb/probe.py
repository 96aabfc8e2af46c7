"""A database is read in a child process before a process of ours touches it.

The HDF5 library itself segfaults or never returns on some corrupt files (byte flips in
attribute messages, found by ``tools/fuzz_databases.py``), and no check of ours can run
before its reads. :func:`probe` runs ``python -m dynatex.tiledb.probe FILE`` in a fresh
interpreter (safe in a process with threads, and on every platform, unlike ``fork``),
which opens the file, validates every method and reads every stored frame:

- the child exits 0: the file is safe to read here;
- it exits 1 (an ordinary error, a :class:`~dynatex.tiledb.TileDBError` for instance): the
  probe says nothing, and opening the file here reports the error;
- it runs out of memory (a ``MemoryError``, exit status 3, or killed by ``SIGKILL`` that the
  probe did not send, the kernel's out-of-memory killer's signal):
  :class:`~dynatex.tiledb.TileDBFormatError`, "reading the file ran out of memory", with the
  child's peak resident memory; this verdict is not remembered (memory comes and goes);
- it is killed by any other signal or overruns its time (30 s plus 1 s per 20 MB of file):
  :class:`~dynatex.tiledb.TileDBFormatError`, "the HDF5 library crashed reading the file" or
  "did not finish within N s".

The child reads with the parent's bound on declared bytes per read (``max_bytes``), and refuses
what the parent's open refuses before reading anything (:func:`~dynatex.tiledb._check.survey`).

A file that passed is remembered by its identity (path, device, inode, size, modification
time), dynatex's version and the bound it was read under (a pass holds for every smaller
bound), in this process and in the user's cache folder (``databases.json`` beside the OpenCL
device verdicts), so a game pays the probe once per new database file, not at every start; a
file the writer has just written and read back is remembered without a probe, for any bound
(:func:`remember`). Where no Python interpreter can be started (Python
embedded in an application whose executable is not Python, and ``DYNATEX_PYTHON`` unset)
the probe is skipped.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from .errors import TileDBFormatError

#: seconds a probe may take: this plus one second per PROBE_BYTES_PER_S of file
PROBE_TIMEOUT_S = 30.0
PROBE_BYTES_PER_S = 20 * 2**20
#: files that passed, remembered in the cache folder (the oldest are dropped beyond this)
MAX_REMEMBERED = 512

_lock = threading.Lock()
_known: dict[tuple[str, float], str | None] = {}  # (identity, bound) -> the problem found (None: safe)


def cache_dir() -> Path:
    """The user's cache folder of dynatex: ``$DYNATEX_CACHE_DIR``, else the platform's."""
    root = os.environ.get("DYNATEX_CACHE_DIR")
    if root:
        return Path(root)
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local"))
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "dynatex"


def probe(filename: str, max_bytes: float = float("inf")) -> None:
    """Raise :class:`TileDBFormatError` when reading ``filename`` (at most ``max_bytes`` declared
    bytes per read) crashes, hangs or exhausts the memory of a child process."""
    key = _identity(filename)
    with _lock:
        problem = _known.get((key, max_bytes), ...)
        if problem is ...:
            problem = None if _passed(key, max_bytes) else _run_child(filename, os.stat(filename).st_size, max_bytes)
            if problem is None:
                _remember(key, max_bytes)
            if problem is None or OUT_OF_MEMORY not in problem:
                _known[key, max_bytes] = problem
    if problem:
        raise TileDBFormatError(problem, filename=filename)


def remember(filename: str) -> None:
    """Record ``filename`` as safe to read without a probe, at any bound: the writer calls this for a
    file it has just written and read back, all of it, in this process (had its reads crashed, so
    would have we)."""
    key = _identity(filename)
    with _lock:
        _known[key, float("inf")] = None
        _remember(key, float("inf"))


def _identity(filename: str) -> str:
    """What a verdict is kept under: the file's path, device, inode, size, modification time and dynatex's version."""
    from .. import __version__

    st = os.stat(filename)
    return "|".join(
        str(v) for v in (os.path.realpath(filename), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, __version__)
    )


def _passed(key: str, max_bytes: float) -> bool:
    """Whether ``key`` passed a probe in this process or an earlier one at a bound of ``max_bytes``
    or more (reads under a smaller bound are a part of those)."""
    if any(k == key and bound >= max_bytes and v is None for (k, bound), v in _known.items()):
        return True
    for entry in _remembered():
        ident, _, bound = entry.rpartition("|")
        try:
            if ident == key and float(bound) >= max_bytes:
                return True
        except ValueError:
            continue
    return False


#: words of the out-of-memory verdict (never remembered)
OUT_OF_MEMORY = "ran out of memory"
#: the child's exit status for a MemoryError
_EXIT_MEMORY = 3


def _run_child(filename: str, size: int, max_bytes: float = float("inf")) -> str | None:
    """The problem a child reading ``filename`` ran into (a crash, a hang, no memory), else None."""
    python = os.environ.get("DYNATEX_PYTHON") or sys.executable
    if not python or "python" not in Path(python).name.lower():
        return None  # no interpreter to run the child with: read here unprobed
    timeout = PROBE_TIMEOUT_S + size / PROBE_BYTES_PER_S
    env = dict(os.environ)
    env.pop("PYTHONFAULTHANDLER", None)
    try:
        proc = subprocess.Popen(
            [python, "-m", "dynatex.tiledb.probe", os.path.abspath(filename), repr(float(max_bytes))],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=os.name == "posix",
        )
    except OSError:
        return None
    try:
        status, peak = _wait(proc, timeout)
    except subprocess.TimeoutExpired:
        _kill(proc)
        return f"reading the file did not finish within {timeout:.0f} s (the HDF5 library loops on it): it is corrupt"
    if status in (0, 1):
        return None
    if status == _EXIT_MEMORY or status == -signal.SIGKILL:
        return (
            f"reading the file {OUT_OF_MEMORY} in a child process (peak resident memory {peak / 2**20:.0f} MiB"
            f"{', killed by SIGKILL' if status < 0 else ''}); free memory, or lower max_bytes to refuse it at once"
        )
    how = f"signal {-status}" if status < 0 else f"exit status {status}"
    return f"the HDF5 library crashed ({how}) reading the file: it is corrupt"


def _wait(proc: subprocess.Popen, timeout: float) -> tuple[int, int]:
    """The child's exit status and peak resident bytes (0 where the platform does not say)."""
    if not hasattr(os, "wait4"):
        return proc.wait(timeout), 0
    deadline = time.monotonic() + timeout
    delay = 0.001
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return proc.returncode, int(usage.ru_maxrss) * (1 if sys.platform == "darwin" else 1024)
        if time.monotonic() >= deadline:
            raise subprocess.TimeoutExpired(proc.args, timeout)
        time.sleep(delay)
        delay = min(delay * 2, 0.05)


def _kill(proc: subprocess.Popen) -> None:
    try:
        if os.name == "posix":
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.kill()
    except OSError:
        pass
    proc.wait()


def _cache_file() -> Path:
    return cache_dir() / "databases.json"


def _remembered() -> list[str]:
    try:
        data = json.loads(_cache_file().read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    return [k for k in data if isinstance(k, str)] if isinstance(data, list) else []


def _remember(key: str, max_bytes: float) -> None:
    """Add ``key`` read at ``max_bytes`` to the files known to be safe (best effort: a read-only
    cache folder only costs time)."""
    key = f"{key}|{float(max_bytes)!r}"
    path = _cache_file()
    known = [k for k in _remembered() if k != key] + [key]
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(known[-MAX_REMEMBERED:], indent=0), encoding="utf-8")
        os.replace(tmp, path)
    except OSError:
        pass


def _main(argv: list[str]) -> int:
    """The child: open ``argv[0]`` and read all of it with at most ``argv[1]`` declared bytes per read
    (default: no bound); 0 when that worked, 3 when memory ran out, 1 on any other ordinary error."""
    from .database import TileDB

    try:
        with TileDB(argv[0], probe=False, max_bytes=float(argv[1]) if len(argv) > 1 else float("inf")) as db:
            errors = db.validate(every_frame=True, keep_going=True)  # every part a reader may read
    except MemoryError:
        return _EXIT_MEMORY
    except Exception:  # noqa: BLE001 - any ordinary error: the parent reports it by opening the file itself
        return 1
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
