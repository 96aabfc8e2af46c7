"""A database is read in a child process before a process of ours touches it.

The HDF5 library itself segfaults or never returns on some corrupt files (byte flips in
attribute messages, found by ``tools/fuzz_databases.py``), and no check of ours can run
before its reads. :func:`probe` runs :func:`~dynatex.tiledb.database.read_everything` in a
child process (:func:`dynatex.child.call`, a fresh interpreter), which opens the file,
validates every method and reads every stored frame:

- the child exits 0: the file is safe to read here;
- it exits 1 (an ordinary error, a :class:`~dynatex.tiledb.TileDBError` for instance): the
  probe says nothing, and opening the file here reports the error;
- it runs out of memory (a ``MemoryError``, or killed by ``SIGKILL`` that the
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
bound), in this process and in the user's cache folder (``databases.json`` in
:func:`dynatex.cache.cache_dir`, beside the OpenCL device verdicts), so a game pays the probe
once per new database file, not at every start; a file the writer has just written and read
back is remembered without a probe, for any bound (:func:`remember`). Where no Python
interpreter can be started (Python embedded in an application whose executable is not Python,
and ``DYNATEX_PYTHON`` unset) the probe is skipped.
"""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path

from ..cache import cache_dir
from ..child import MEMORY_STATUS, call
from ..errors import ChildStartError
from .errors import TileDBFormatError

#: seconds a probe may take: this plus one second per PROBE_BYTES_PER_S of file
PROBE_TIMEOUT_S = 30.0
PROBE_BYTES_PER_S = 20 * 2**20
#: files that passed, remembered in the cache folder (the oldest are dropped beyond this)
MAX_REMEMBERED = 512

_lock = threading.Lock()
_known: dict[tuple[str, float], str | None] = {}  # (identity, bound) -> the problem found (None: safe)


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
#: what the child runs (:func:`dynatex.tiledb.database.read_everything`), named, not imported: the
#: reader imports the probe
READER = "dynatex.tiledb.database:read_everything"


def _run_child(filename: str, size: int, max_bytes: float = float("inf")) -> str | None:
    """The problem a child reading ``filename`` ran into (a crash, a hang, no memory), else None."""
    timeout = PROBE_TIMEOUT_S + size / PROBE_BYTES_PER_S
    try:
        child = call(READER, os.path.abspath(filename), float(max_bytes), timeout=timeout)
    except ChildStartError:
        return None  # no interpreter to run the child with: read here unprobed
    if child.timed_out:
        return f"reading the file did not finish within {timeout:.0f} s (the HDF5 library loops on it): it is corrupt"
    if child.status in (0, 1):
        return None
    if child.status == MEMORY_STATUS or child.status == -signal.SIGKILL:
        return (
            f"reading the file {OUT_OF_MEMORY} in a child process (peak resident memory "
            f"{child.peak_bytes / 2**20:.0f} MiB{', killed by SIGKILL' if child.status < 0 else ''}); free memory, "
            "or lower max_bytes to refuse it at once"
        )
    how = f"signal {-child.status}" if child.status < 0 else f"exit status {child.status}"
    return f"the HDF5 library crashed ({how}) reading the file: it is corrupt"


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
