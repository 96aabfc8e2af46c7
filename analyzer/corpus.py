"""Analysing a corpus of clips: one task per clip, in process or on a Dask cluster.

Each task opens its clip and writes its own database (through the atomic
:class:`~dynatex.tiledb.DatabaseWriter`) inside the task, so no HDF5 handle ever crosses a
process; what comes back is a :class:`ClipResult`, plain data. A clip whose database is
already complete (valid, every method present, same source hash and frame selection) is
skipped. A clip that fails is reported with a one-line reason and the others go on.
:func:`merge_databases` then gathers the textures into one database, in one process.

Dask (``dask.distributed``) is optional (``pip install dynatex[dask]``) and imported only
when a scheduler other than ``"none"`` is asked for.
"""

from __future__ import annotations

import glob
import hashlib
import os
import re
import sys
import time
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from ..errors import InvalidArgumentError
from ..tiledb import DatabaseWriter, TileDB, TileDBError
from ..tiledb.schema import texture_names_from_paths
from ..tiledb.writer import remove_stale_temp_files
from .errors import SchedulerError
from .methods import Clips, Method, get_method
from .stream import parse_bytes

#: File suffixes taken as clips when a folder of clips is given.
CLIP_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg", ".wmv", ".gif", ".npy")
#: Methods learned from a clip on disk when ``max_memory`` is set (the others need the frames in memory).
STREAMED_METHODS = ("lds", "mixture")

OK, SKIPPED, FAILED = "ok", "skipped", "failed"
#: Thread-count variables of the BLAS libraries numpy may use, set for local workers.
BLAS_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
#: Seconds to reach a scheduler named by address before :class:`SchedulerError`.
SCHEDULER_TIMEOUT_S = 20


@dataclass(frozen=True)
class ClipTask:
    """Everything one clip's task needs, picklable: paths, methods and their parameters."""

    clip: str
    texture: str
    database: str
    methods: tuple[str, ...]
    params: dict = field(default_factory=dict)  # method -> keyword arguments of its learn function
    load: dict = field(default_factory=dict)  # start, stop, step, crop, size, color
    max_memory: int | None = None
    spill_dir: str | None = None
    skip_complete: bool = True


@dataclass
class ClipResult:
    """One row of the corpus summary."""

    clip: str
    texture: str
    database: str
    methods: tuple[str, ...]
    seconds: float
    status: str  # "ok", "skipped" or "failed"
    reason: str = ""  # one line, for a failed clip
    worker: str = ""

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["methods"] = list(self.methods)
        return d


# -- finding clips --------------------------------------------------------------------
def find_clips(specs: Iterable[str | os.PathLike]) -> list[str]:
    """Clip paths from paths, globs, folders of clips and text files listing clips (one per line).

    A folder whose files include clips (by suffix, :data:`CLIP_SUFFIXES`) stands for those
    clips, not recursively; any other folder is one clip (a folder of images). A ``.txt``
    file lists paths or globs, one per line (``#`` starts a comment), relative to its folder.
    Paths are returned once each, in the order given.
    """
    found: list[str] = []
    for spec in specs:
        found.extend(_expand(os.fspath(spec), depth=0))
    seen: set[str] = set()
    out = []
    for p in found:
        key = os.path.abspath(p)
        if key not in seen:
            seen.add(key)
            out.append(p)
    if not out:
        raise FileNotFoundError("no clips found in " + ", ".join(os.fspath(s) for s in specs))
    return out


def _expand(spec: str, depth: int) -> list[str]:
    if glob.has_magic(spec) and not os.path.exists(spec):
        hits = sorted(glob.glob(spec))
        if not hits:
            raise FileNotFoundError(f"{spec}: the pattern matches no clip")
        return [h for hit in hits for h in _expand(hit, depth)]
    if not os.path.exists(spec):
        raise FileNotFoundError(f"{spec}: no such clip file or folder")
    if os.path.isdir(spec):
        clips = sorted(
            os.path.join(spec, n)
            for n in os.listdir(spec)
            if n.lower().endswith(CLIP_SUFFIXES) and os.path.isfile(os.path.join(spec, n))
        )
        return clips or [spec]
    if spec.lower().endswith(".txt"):
        if depth > 0:
            raise InvalidArgumentError(f"{spec}: a clip list may not name another list")
        base = os.path.dirname(spec)
        out = []
        with open(spec, encoding="utf-8") as f:
            for number, line in enumerate(f, 1):
                line = line.split("#", 1)[0].strip()
                if line:
                    path = line if os.path.isabs(line) else os.path.join(base, line)
                    try:
                        out.extend(_expand(path, depth + 1))
                    except (FileNotFoundError, ValueError) as exc:
                        raise type(exc)(f"{spec}:{number}: {exc}") from None
        return out
    return [spec]


# -- one clip -----------------------------------------------------------------------------
def analyze_clip(task: ClipTask) -> ClipResult:
    """Run one clip's task: skip it when its database is complete, else learn and write it.

    Never raises for a bad clip: the result says ``failed`` with a one-line reason.
    """
    t0 = time.perf_counter()
    worker = _worker_name()
    try:
        remove_stale_temp_files(task.database)
        if task.skip_complete and database_is_complete(task):
            return ClipResult(
                task.clip, task.texture, task.database, task.methods, time.perf_counter() - t0, SKIPPED, worker=worker
            )
        _learn_and_write(task)
    except Exception as exc:  # noqa: BLE001 - a failed clip is a row of the summary, not the end of the run
        return ClipResult(
            task.clip,
            task.texture,
            task.database,
            task.methods,
            time.perf_counter() - t0,
            FAILED,
            reason=_reason(exc),
            worker=worker,
        )
    return ClipResult(task.clip, task.texture, task.database, task.methods, time.perf_counter() - t0, OK, worker=worker)


def _learn_and_write(task: ClipTask) -> None:
    with DatabaseWriter(task.database, overwrite=True) as writer:
        learn_into(
            writer,
            task.texture,
            task.clip,
            task.methods,
            params=task.params,
            load=task.load,
            max_memory=task.max_memory,
            spill_dir=task.spill_dir,
        )


def learn_into(
    writer: DatabaseWriter,
    texture: str,
    path: str,
    methods: Sequence[str],
    *,
    params: dict[str, dict] | None = None,
    load: dict | None = None,
    max_memory: int | None = None,
    spill_dir: str | None = None,
    isolate: bool = True,
    progress: Callable[[str], Any] | None = None,
    on_model: Callable[[str, Any, float], None] | None = None,
) -> Any:
    """Read clip ``path`` and put texture ``texture`` with each of ``methods`` into ``writer``.

    With ``max_memory`` the clip is spilled to disk and LDS and the mixture learn out of
    core; other methods read the frames into memory only where they fit the bound.
    ``params`` holds each method's keyword arguments; a clip-valued parameter (kind
    :class:`~dynatex.analyzer.methods.Clips`, the tiles' ``mix``) may hold paths, decoded
    here right after the main clip with its ``load`` options except ``start`` and ``crop``
    (another video need not have that frame or that region). ``progress(stage)`` gives a
    ``progress(done, total)`` callback per stage ("decode" and each method);
    ``on_model(method, model, seconds)`` sees each model once it is written.
    Returns the source description written.
    """
    chosen = [get_method(m) for m in methods]
    params = params or {}
    load = dict(load or {})
    from .video import load_clip_path

    bar = progress or (lambda stage: None)
    disk = None
    clip = None
    try:
        if max_memory is not None:
            from .stream import spill_clip

            disk = spill_clip(path, folder=spill_dir, isolate=isolate, progress=bar("decode"), **load)
            source = disk.source_info()
        else:
            clip = load_clip_path(path, isolate=isolate, progress=bar("decode"), **load)
            source = clip.source_info()
        params = {m.name: _decode_clip_params(m, params.get(m.name, {}), isolate, load) for m in chosen}
        writer.put_texture(texture, source)
        frames_written = False
        for m in chosen:
            t = time.perf_counter()
            kwargs = dict(params.get(m.name, {}))
            if disk is not None and m.name in STREAMED_METHODS:
                data = disk
                kwargs["max_memory"] = max_memory
            else:
                if clip is None:
                    clip = _from_disk(disk, m.name, max_memory)
                data = clip
            if m.needs_frames and not frames_written:
                writer.put_frames(texture, clip.frames)
                frames_written = True
            model = m.function()(data, progress=bar(m.name), **kwargs)
            writer.put_method(texture, m.name, model)
            if on_model is not None:
                on_model(m.name, model, time.perf_counter() - t)
            del model
    finally:
        if disk is not None:
            disk.close()
    return source


def _decode_clip_params(method: Method, kwargs: dict, isolate: bool, load: dict) -> dict:
    """``kwargs`` with the clip paths of ``method``'s :class:`~dynatex.analyzer.methods.Clips` parameters decoded."""
    from .video import load_clip_path

    kwargs = dict(kwargs)
    options = {k: v for k, v in load.items() if k not in ("start", "crop")}
    for p in method.params:
        if isinstance(p.kind, Clips) and kwargs.get(p.name):
            kwargs[p.name] = [
                load_clip_path(c, isolate=isolate, **options) if isinstance(c, str) else c for c in kwargs[p.name]
            ]
    return kwargs


def _from_disk(disk, method: str, max_memory: int):
    """The frames of a spilled clip in memory, for a method that needs them, if they fit the bound."""
    from .video import Clip

    need = 6 * disk.nbytes  # the uint8 frames and a float32 working copy, with slack
    if need > max_memory:
        raise MemoryError(
            f"method {method} needs the clip in memory (about {need / 2**30:.2f} GiB), more than "
            f"max_memory {max_memory / 2**30:.2f} GiB; only {', '.join(STREAMED_METHODS)} learn "
            f"out of core"
        )
    return Clip(frames=disk.frames(), **disk.source())


def database_is_complete(task: ClipTask) -> bool:
    """Whether ``task.database`` is valid and holds the task's texture with every method, learned
    from the same source (same content hash, frame selection and geometry)."""
    if not os.path.isfile(task.database):
        return False
    try:
        with TileDB(task.database) as db:
            db.validate()
            if task.texture not in db:
                return False
            tex = db.texture(task.texture)
            src = tex.source
            if not set(task.methods) <= set(tex.methods):
                return False
    except (TileDBError, OSError):
        return False
    load = task.load
    crop = tuple(load["crop"]) if load.get("crop") else ()
    size = tuple(load["size"]) if load.get("size") else None
    channels = 3 if load.get("color", True) else 1
    if (src.frame_start, src.frame_step, src.crop, src.channels) != (
        load.get("start", 0),
        load.get("step", 1),
        crop,
        channels,
    ):
        return False
    if size is not None and (src.height, src.width) != size:
        return False
    try:
        return src.sha256 == clip_sha256(task.clip, load.get("start", 0), load.get("stop"), load.get("step", 1))
    except OSError:
        return False


def clip_sha256(path: str, start: int = 0, stop: int | None = None, step: int = 1) -> str:
    """The content hash :func:`~dynatex.analyzer.load_clip` records for a clip, without decoding it."""
    from .video import IMAGE_SUFFIXES, _file_digest

    if os.path.isdir(path):
        names = sorted(n for n in os.listdir(path) if n.lower().endswith(IMAGE_SUFFIXES))[start:stop:step]
        h = hashlib.sha256()
        for n in names:
            _file_digest(os.path.join(path, n), h)
        return h.hexdigest()
    if path.endswith(".npy"):
        import numpy as np

        from .video import load_npy, npy_header

        _, fortran, _, offset = npy_header(path)
        if fortran:
            return hashlib.sha256(np.ascontiguousarray(load_npy(path)).data).hexdigest()
        h = hashlib.sha256()
        with open(path, "rb") as f:
            f.seek(offset)
            for block in iter(lambda: f.read(1 << 22), b""):
                h.update(block)
        return h.hexdigest()
    return _file_digest(path).hexdigest()


def _reason(exc: BaseException) -> str:
    text = str(exc)
    if isinstance(exc, KeyError) and text.startswith("'") and text.endswith("'"):
        text = text[1:-1]
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    line = lines[0] if lines else type(exc).__name__
    if not isinstance(exc, (ValueError, OSError, KeyError, TypeError, MemoryError, TileDBError)):
        line = f"internal error: {type(exc).__name__}: {line}"
    return line


def _worker_name() -> str:
    if "distributed" not in sys.modules:  # not on a Dask worker; do not import Dask for nothing
        return ""
    from distributed import get_worker

    try:
        return str(get_worker().name)
    except ValueError:
        return ""


# -- the corpus ---------------------------------------------------------------------------
def analyze_corpus(
    clips: Iterable[str | os.PathLike],
    output_dir: str | os.PathLike,
    *,
    methods: Sequence[str] | Callable[[str], Sequence[str]] = ("lds",),
    params: dict[str, dict] | None = None,
    load: dict | None = None,
    scheduler: str = "none",
    workers: int | None = None,
    merge: str | os.PathLike | None = None,
    max_memory: int | str | None = None,
    spill_dir: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
    client: Any = None,
) -> list[ClipResult]:
    """Analyse many clips, one database per clip in ``output_dir``; return the summary table.

    Parameters
    ----------
    clips : iterable of paths
        Clips, globs, folders of clips or ``.txt`` lists (see :func:`find_clips`).
    output_dir : path
        Folder of the per-clip databases ``TEXTURE.h5`` (created when missing).
    methods : sequence of str, or callable(clip path) -> sequence of str
        Methods run on every clip, or per clip.
    params : dict, optional
        Keyword arguments per method name, passed to its learn function.
    load : dict, optional
        Clip reading options: ``start``, ``stop``, ``step``, ``crop``, ``size``, ``color``.
    scheduler : str
        ``"none"`` (in this process, one clip after the other), ``"local"`` (a
        ``dask.distributed.LocalCluster`` of ``workers`` processes, BLAS threads split
        between them) or a scheduler address ``"tcp://host:port"``.
    workers : int, optional
        Workers of a local cluster (default: the CPU count, at most the number of clips).
    merge : path, optional
        Gather every analysed texture into this database afterwards (atomic; other
        textures in it are kept unless ``overwrite``).
    max_memory : int or str, optional
        Bound per clip (``"2GB"``): LDS and the mixture's PCA learn out of core from a
        spilled copy of the clip in ``spill_dir``; other methods fail on clips too large for it.
    overwrite : bool
        Analyse every clip again, even where its database is complete, and start the
        ``merge`` database afresh.
    progress : bool
        A progress bar across the corpus on stderr (when it is a terminal).
    client : dask.distributed.Client, optional
        Use this client instead of making one (``scheduler`` is then ignored).

    Returns
    -------
    list of ClipResult
        One row per clip, in the order of ``clips``.
    """
    paths = find_clips(clips)
    out = os.path.abspath(os.fspath(output_dir))
    os.makedirs(out, exist_ok=True)
    bound = None if max_memory is None else parse_bytes(max_memory)
    load = dict(load or {})
    load.setdefault("color", True)
    tasks = []
    for path, name in zip(paths, texture_names_from_paths(paths)):
        chosen = tuple(methods(path) if callable(methods) else methods)
        if not chosen:
            raise InvalidArgumentError(f"{path}: no method to run")
        for m in chosen:
            get_method(m)
        tasks.append(
            ClipTask(
                clip=os.path.abspath(path),
                texture=name,
                database=os.path.join(out, f"{name}.h5"),
                methods=chosen,
                params={m: dict((params or {}).get(m, {})) for m in chosen},
                load=load,
                max_memory=bound,
                spill_dir=spill_dir,
                skip_complete=not overwrite,
            )
        )
    if client is not None:
        results = _run_dask(client, tasks, progress)
    elif scheduler == "none":
        results = _run_local(tasks, progress)
    else:
        with connect(scheduler, workers, len(tasks)) as c:
            results = _run_dask(c, tasks, progress)
    if merge is not None:
        merge_databases(results, merge, overwrite=overwrite)
    return results


def _run_local(tasks: list[ClipTask], progress: bool) -> list[ClipResult]:
    bar = _bar(len(tasks), progress)
    results = []
    for task in tasks:
        results.append(analyze_clip(task))
        bar.update(1)
    bar.close()
    return results


def blas_threads(workers: int) -> int:
    """BLAS threads per worker so that ``workers`` workers together use the machine's cores once."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


def connect(scheduler: str, workers: int | None, n_tasks: int):
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError:
        raise ImportError("--scheduler local or an address needs Dask: pip install 'dynatex[dask]'") from None
    if scheduler == "local":
        n = workers or max(1, min(os.cpu_count() or 1, n_tasks))
        threads = blas_threads(n)
        # Set before a worker process starts (numpy's BLAS reads them once, at import); workers
        # that are not daemons may start a child to decode a hostile video safely.
        blas = {k: str(threads) for k in BLAS_VARIABLES}
        environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **blas}
        # Dask's nanny lets the variables of this process override its pre-spawn ones (and
        # leaves its own in this process), so both are set while the workers start.
        saved = {k: os.environ.get(k) for k in BLAS_VARIABLES}
        os.environ.update(blas)
        try:
            with dask.config.set({"distributed.nanny.pre-spawn-environ": environ, "distributed.worker.daemon": False}):
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        return _OwnedClient(Client(cluster), cluster)
    if not re.match(r"^[a-z+]+://", scheduler):
        raise InvalidArgumentError(
            f"scheduler must be 'none', 'local' or an address like tcp://host:8786, not {scheduler!r}"
        )
    try:
        return _OwnedClient(Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S}s"), None)
    except OSError as exc:
        raise SchedulerError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None


class _OwnedClient:
    """A client (and the local cluster it runs on) closed together."""

    def __init__(self, client, cluster) -> None:
        self.client, self.cluster = client, cluster

    def __enter__(self):
        return self.client

    def __exit__(self, *exc) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def _run_dask(client, tasks: list[ClipTask], progress: bool) -> list[ClipResult]:
    from distributed import as_completed

    run = uuid.uuid4().hex[:8]
    futures = client.map(analyze_clip, tasks, pure=False, key=[f"analyze-{t.texture}-{run}" for t in tasks])
    index = {f.key: i for i, f in enumerate(futures)}
    results: list[ClipResult | None] = [None] * len(tasks)
    bar = _bar(len(tasks), progress)
    for fut in as_completed(futures):
        i = index[fut.key]
        task = tasks[i]
        if fut.status == "finished":
            results[i] = fut.result()
        else:
            try:
                exc = fut.exception()
            except Exception as err:  # noqa: BLE001 - a cancelled future raises instead of returning
                exc = err
            reason = _reason(exc)
            if type(exc).__name__ == "KilledWorker":
                reason = f"the worker analysing it died repeatedly (killed, or a decoder crash): {reason}"
            results[i] = ClipResult(task.clip, task.texture, task.database, task.methods, 0.0, FAILED, reason)
        bar.update(1)
    bar.close()
    return results  # type: ignore[return-value]


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _bar(total: int, enabled: bool):
    if not enabled or not sys.stderr.isatty():
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="clips", unit="clip", file=sys.stderr)


# -- merging and the summary ----------------------------------------------------------------
def merge_databases(results: Sequence[ClipResult], path: str | os.PathLike, *, overwrite: bool = False) -> int:
    """Gather the textures of the analysed (and skipped) clips into one database, atomically.

    Models are read (and so validated) from each clip's database and written through the
    :class:`~dynatex.tiledb.DatabaseWriter`; returns the number of textures merged.
    """
    done = [r for r in results if r.status in (OK, SKIPPED)]
    with DatabaseWriter(path, overwrite=overwrite) as writer:
        for r in done:
            with TileDB(r.database) as db:
                tex = db.texture(r.texture)
                writer.put_texture(r.texture, tex.source)
                if tex.has_frames:
                    writer.put_frames(r.texture, tex.frames().read())
                for m in tex.methods:
                    writer.put_method(r.texture, m, tex.read(m))
    return len(done)


def format_table(results: Sequence[ClipResult]) -> str:
    """The summary as a text table: clip, methods, seconds, status (and the reason of a failure)."""
    rows = [("clip", "methods", "seconds", "status")]
    for r in results:
        status = r.status if not r.reason else f"{r.status}: {r.reason}"
        rows.append((os.path.basename(os.path.normpath(r.clip)), ",".join(r.methods), f"{r.seconds:.1f}", status))
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    lines = [f"{a:<{widths[0]}}  {b:<{widths[1]}}  {c:>{widths[2]}}  {d}" for a, b, c, d in rows]
    n_fail = sum(r.status == FAILED for r in results)
    n_skip = sum(r.status == SKIPPED for r in results)
    lines.append(
        f"{len(results)} clips: {len(results) - n_fail - n_skip} analysed, {n_skip} skipped "
        f"(database complete), {n_fail} failed"
    )
    return "\n".join(lines)
