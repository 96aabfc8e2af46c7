"""Writing a tile database atomically: a temporary file in the same folder, then a rename.

An interrupted or failed write leaves the previous database exactly as it was. A write killed
outright (``kill -9``, a power cut) leaves its temporary file ``.NAME.XXXXXXXX.tmp`` behind;
every writer holds a shared ``flock`` on its own temporary file while it lives, so the next
writer of ``NAME`` recognises the leftovers (that exact name pattern, a lock nobody holds) and
removes them. Locks die with their process, so a crash can never make a live file look stale
or a stale one look live. On NFS ``flock`` is emulated with POSIX locks, which reach across
machines but lapse when the writer's HDF5 handle closes; a writer that starts in that moment
can take the file, and the first writer's commit then fails (the database stays as it was).

Writers of one database serialise their commits on a lock file ``.NAME.lock`` beside it (an
exclusive ``flock``, held from re-reading the current database to the rename; the holder removes
the file): a commit carries over every texture the database holds *at that moment*, so writers
that ran side by side (two analyses, a merge) keep each other's textures. A writer that waits
says so once on stderr. On NFS the lock works across machines only where the server runs a lock
manager (NFSv4, or NFSv3 with ``lockd``; not with the ``nolock`` mount option): elsewhere writers
on different machines are not serialised and the last commit wins.
Where there is no ``fcntl`` (Windows) nothing is locked or removed.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import secrets
import stat
import sys
import unicodedata
from typing import Any

import h5py
import numpy as np

from ..errors import InvalidArgumentError
from ..stale import hold, release, remove_unheld
from . import frames as _frames
from . import probe as _probe
from . import schema
from . import source as _source
from .codecs import CODECS
from .database import TileDB
from .errors import TextureNotFoundError, TileDBWriteError
from .source import SourceInfo

try:
    import fcntl
except ImportError:  # pragma: no cover (not POSIX)
    fcntl = None  # type: ignore[assignment]

#: texture attributes written by ``--methods auto`` (FORMAT.md): the mode a player opens by default, and why
DEFAULT_MODE = "default_mode"
RANKING = "ranking"
MAX_RANKING = 65536  # characters of the ranking's JSON

#: ``tempfile.mkstemp``'s alphabet and length, so files left by earlier writers are recognised too.
_TMP_CHARS = "abcdefghijklmnopqrstuvwxyz0123456789_"
_TMP_LEN = 8


class DatabaseWriter:
    """Create or update a database; nothing reaches ``path`` until :meth:`commit`.

    Used as a context manager, it commits on success and discards on an exception.
    Textures already in ``path`` are kept unless replaced or removed.

    Examples
    --------
    >>> with DatabaseWriter("out.h5") as w:          # doctest: +SKIP
    ...     w.put_texture("water", source_info)
    ...     w.put_method("water", "lds", model)
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = False) -> None:
        self.path = os.path.abspath(os.fspath(path))
        folder = os.path.dirname(self.path)
        if not os.path.isdir(folder):
            raise FileNotFoundError(f"{path}: folder {folder} does not exist")
        if os.path.isdir(self.path):
            raise IsADirectoryError(f"{path}: is a folder, not a database file")
        # Validate the existing database before touching anything; commit re-reads it if it changed.
        self._overwrite = overwrite
        self._old: TileDB | None = None
        self._old_id: tuple[int, ...] | None = None
        if os.path.exists(self.path) and not overwrite:
            self._old_id = _identity(self.path)
            self._old = TileDB(self.path)
        self._file: h5py.File | None = None
        self._tmp, self._lock = "", None
        self._removed: set[str] = set()
        try:
            with self._writing():
                remove_stale_temp_files(self.path)
                self._tmp, self._lock = _create_temp(self.path)
                self._file = _open_for_writing(self._tmp, self._lock)
                self._file.attrs[schema.ATTR_FORMAT] = schema.FORMAT_NAME
                self._file.attrs[schema.ATTR_VERSION] = np.asarray(schema.COMPATIBLE_VERSION, np.int32)  # and at commit
                from . import __version__

                self._file.attrs[schema.ATTR_CREATED_BY] = f"dynatex {__version__}"
                self._textures = self._file.create_group(schema.TEXTURES)
        except BaseException:
            self.abort()
            raise

    # -- textures --------------------------------------------------------------
    def put_texture(self, name: str, source: SourceInfo) -> None:
        """Create texture ``name`` afresh (replacing any texture of that name) with its source description."""
        self._check_open()
        name = _check_name(name)
        if name in self._textures:
            del self._textures[name]
        self._removed.add(name)  # the old file's copy is not carried over
        with self._writing():
            g = self._textures.create_group(name)
            _source.write(g.create_group(schema.SOURCE), source)

    def remove_texture(self, name: str) -> None:
        self._check_open()
        name = _nfc(name)
        if name not in self._textures and not (self._old and name in self._old and name not in self._removed):
            raise TextureNotFoundError(f"no texture named {name!r}", filename=self.path)
        if name in self._textures:
            del self._textures[name]
        self._removed.add(name)

    def put_method(self, name: str, method: str, model: Any) -> None:
        """Store ``model`` as texture ``name``'s ``method`` group, replacing an earlier one."""
        self._check_open()
        if method not in CODECS:
            raise InvalidArgumentError(f"method must be one of {sorted(CODECS)}, not {method!r}")
        with self._writing():
            g = self._texture_group(name, skip=method)
            if method in g:
                del g[method]
            CODECS[method].write(g.create_group(method), model)

    def put_frames(self, name: str, frames: np.ndarray) -> None:
        """Store the source frames texture ``name``'s gather-based methods play from."""
        self._check_open()
        with self._writing():
            g = self._texture_group(name, skip=schema.FRAMES)
            if schema.FRAMES in g:
                del g[schema.FRAMES]
            _frames.write(g, schema.FRAMES, frames)

    def put_default_mode(self, name: str, mode: str, ranking: list[dict] | None = None) -> None:
        """Mark ``mode`` as texture ``name``'s default player mode (attribute ``default_mode``), with
        the ``ranking`` that chose it as a JSON attribute (``dynatex analyze --methods auto``)."""
        if not isinstance(mode, str) or not re.fullmatch(r"[a-z][a-z0-9_]{0,31}", mode):
            raise InvalidArgumentError(f"default mode must be a mode name (lower-case letters), not {mode!r}")
        text = None if ranking is None else json.dumps(ranking, allow_nan=False, separators=(",", ":"))
        if text is not None and len(text) > MAX_RANKING:
            raise InvalidArgumentError(f"ranking of texture {name!r} is {len(text)} characters, above {MAX_RANKING}")
        self._check_open()
        with self._writing():
            g = self._texture_group(name)
            g.attrs[DEFAULT_MODE] = mode
            if text is None:
                g.attrs.pop(RANKING, None)
            else:
                g.attrs[RANKING] = text

    def source(self, name: str) -> SourceInfo:
        from ._check import Checker

        g = self._texture_group(name)
        return _source.read(g[schema.SOURCE], Checker(self._tmp))

    def _texture_group(self, name: str, skip: str | None = None) -> h5py.Group:
        name = _nfc(name)
        if name in self._textures:
            return self._textures[name]
        if self._old is not None and name in self._old and name not in self._removed:
            return self._carry(self._old, name, skip)
        raise TextureNotFoundError(f"no texture named {name!r}; call put_texture first", filename=self.path)

    def _carry(self, db: TileDB, name: str, skip: str | None = None) -> h5py.Group:
        """Copy texture ``name`` of ``db`` (all but ``skip``) into the new file."""
        old = db._file[schema.TEXTURES][name]
        g = self._textures.create_group(name)
        for key in old:
            if key != skip:
                old.copy(old[key], g, name=key)
        for key in (DEFAULT_MODE, RANKING):  # the texture's own attributes
            if key in old.attrs:
                g.attrs[key] = old.attrs[key]
        return g

    # -- commit / abort ----------------------------------------------------------
    def commit(self) -> None:
        """Carry over untouched textures, stamp the format version their content needs
        (:func:`format_version`), validate the new file, and rename it onto ``path``."""
        self._check_open()
        lock = None
        try:
            lock = lock_database(self.path)
            with self._writing():
                if not self._overwrite:
                    current = self._current()
                    if current is not None:
                        for name in current.textures:
                            if name not in self._textures and name not in self._removed:
                                self._carry(current, name)
                self._file.attrs[schema.ATTR_VERSION] = np.asarray(format_version(self._textures), np.int32)
                self._file.close()
                self._file = None
            with TileDB(self._tmp, probe=False, max_bytes=float("inf")) as db:  # written here, just now
                db.validate()
            self._close_old()
            _keep_mode(self._tmp, self.path)
            os.replace(self._tmp, self.path)
            _probe.remember(self.path)  # read back above: no probe needed to open it
        except BaseException:
            self.abort()
            raise
        finally:
            if lock is not None:
                lock.release()
        self._release()

    def _current(self) -> TileDB | None:
        """The database at ``path`` now (under the lock): the one opened at the start when it is
        unchanged, else the file another writer committed since (validated), or None."""
        now = _identity(self.path)
        if now is None:
            self._close_old()
            return None
        if now != self._old_id:
            self._close_old()
            self._old = TileDB(self.path)
            self._old_id = now
        return self._old

    def _close_old(self) -> None:
        if self._old is not None:
            self._old.close()
            self._old = None

    def _check_open(self) -> None:
        if self._file is None:
            raise RuntimeError("writer already committed or aborted")

    @contextlib.contextmanager
    def _writing(self):
        """Turn the system refusing a write (full disk, quota, file size limit) into one line."""
        try:
            yield
        except OSError as exc:
            if exc.errno not in _REFUSED or isinstance(exc, TileDBWriteError):
                raise
            self.abort()  # now, before objects the error holds are freed and flush to the full disk
            folder = os.path.dirname(self.path)
            raise TileDBWriteError(
                f"cannot write the database: {os.strerror(exc.errno).lower()} in {folder}; it is unchanged",
                errno=exc.errno,
                filename=self.path,
            ) from None

    def abort(self) -> None:
        """Discard everything written; ``path`` is left untouched."""
        if self._file is not None:
            file, self._file = self._file, None
            _discard(file)
        self._close_old()
        if self._tmp and os.path.exists(self._tmp):
            os.unlink(self._tmp)
        self._release()

    def _release(self) -> None:
        release(self._lock)  # drops the flock
        self._lock = None

    def __enter__(self) -> DatabaseWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            if self._file is not None:  # not already committed or aborted
                self.commit()
        else:
            self.abort()


#: What the system refuses a write for, outside dynatex: a full disk, a quota, a file size limit.
_REFUSED = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def _discard(file: h5py.File) -> None:
    """Close the HDF5 file of a write being discarded without writing to disk: its descriptor is
    first pointed at an anonymous memory file, so that the flush of cached chunks and metadata that
    closing makes cannot fail on a full disk (HDF5 left half-closed crashes the interpreter at exit)."""
    try:
        fd = file.id.get_vfd_handle()
        spare = os.memfd_create("dynatex-discard") if hasattr(os, "memfd_create") else None
        if spare is not None:
            os.dup2(spare, fd)
            os.close(spare)
    except (OSError, ValueError, RuntimeError):
        pass  # closed already, or another driver: close it as it is
    try:
        file.close()
    except Exception:  # noqa: BLE001, S110 - discarded anyway; closing was what mattered
        pass


def format_version(textures: h5py.Group) -> tuple[int, int]:
    """The version a file with these ``textures`` is: :data:`~.schema.FORMAT_VERSION` where one holds
    a required part (``schema.REQUIRED_PARTS``, which older readers must refuse), else
    :data:`~.schema.COMPATIBLE_VERSION`, which every reader of its major reads."""
    for texture in textures.values():
        for method, parts in schema.REQUIRED_PARTS.items():
            if method in texture and any(part in texture[method] for part in parts):
                return schema.FORMAT_VERSION
    return schema.COMPATIBLE_VERSION


def _nfc(name: str) -> str:
    return unicodedata.normalize("NFC", name) if isinstance(name, str) else name


def _check_name(name: str) -> str:
    """``name`` in NFC, if it is a valid texture name."""
    name = _nfc(name)
    problem = schema.texture_name_problem(name)
    if problem:
        raise InvalidArgumentError(
            f"texture name {name!r} is invalid: it {problem}; a name is {schema.TEXTURE_NAME_RULE}"
        )
    return name


def temp_file_pattern(path: str | os.PathLike) -> re.Pattern[str]:
    """The names of the temporary files a writer of database ``path`` creates beside it."""
    name = os.path.basename(os.fspath(path))
    return re.compile(rf"\.{re.escape(name)}\.[{re.escape(_TMP_CHARS)}]{{{_TMP_LEN}}}\.tmp")


def remove_stale_temp_files(path: str | os.PathLike) -> list[str]:
    """Remove the temporary files that interrupted writers of database ``path`` left behind.

    Only files named by :func:`temp_file_pattern` count, and only those no live writer holds:
    a writer keeps a shared ``flock`` on its file, so an exclusive one is granted on stale files
    alone. Returns the paths removed.
    """
    path = os.path.abspath(os.fspath(path))
    return remove_unheld(os.path.dirname(path), temp_file_pattern(path))


def _create_temp(path: str) -> tuple[str, int | None]:
    """A new temporary file beside ``path``, created with the umask's mode, and what holds it against
    cleaners (:func:`dynatex.stale.hold`)."""
    folder, name = os.path.split(path)
    for _ in range(100):
        token = "".join(secrets.choice(_TMP_CHARS) for _ in range(_TMP_LEN))
        tmp = os.path.join(folder, f".{name}.{token}.tmp")
        try:
            os.close(os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666))
        except FileExistsError:
            continue
        lock = hold(tmp)
        if lock is not None:
            return tmp, lock
        # a cleaner took it between creation and lock: try another name
    raise FileExistsError(f"{path}: cannot create a temporary file in {folder}")


def _open_for_writing(tmp: str, lock: int | None) -> h5py.File:
    """``tmp`` opened by HDF5 for writing without HDF5's own exclusive lock, which would conflict with
    the writer's shared one. An HDF5 too old to open unlocked gets the file with its own lock, which
    protects it from cleaners just as well while it is open."""
    try:
        return h5py.File(tmp, "w", locking=False, rdcc_nbytes=0)
    except ValueError:
        if lock is not None and lock >= 0:
            fcntl.flock(lock, fcntl.LOCK_UN)
        return h5py.File(tmp, "w", rdcc_nbytes=0)


class DatabaseLock:
    """The exclusive lock on writing database ``path`` (see :func:`lock_database`)."""

    def __init__(self, path: str, fd: int | None) -> None:
        self.path, self._fd = path, fd

    def release(self) -> None:
        """Remove the lock file and drop the lock (a writer waiting on the removed file tries again)."""
        if self._fd is not None:
            try:
                os.unlink(self.path)
            except OSError:
                pass
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> DatabaseLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()


def lock_path(path: str | os.PathLike) -> str:
    """The lock file that writers of database ``path`` serialise on: ``.NAME.lock`` beside it."""
    folder, name = os.path.split(os.path.abspath(os.fspath(path)))
    return os.path.join(folder, f".{name}.lock")


def lock_database(path: str | os.PathLike) -> DatabaseLock:
    """Take the exclusive lock on writing database ``path``, waiting for the writer that holds it
    (said once on stderr). A lock file left by a killed writer holds no lock and is taken over."""
    lock = lock_path(path)
    if fcntl is None:
        return DatabaseLock(lock, None)
    said = False
    while True:
        fd = os.open(lock, os.O_RDONLY | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0), 0o666)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if not said:
                    said = True
                    print(f"dynatex: waiting for another writer of {path} to finish", file=sys.stderr, flush=True)
                fcntl.flock(fd, fcntl.LOCK_EX)
            held = os.fstat(fd)
            try:
                now = os.lstat(lock)
            except FileNotFoundError:
                now = None
        except BaseException:
            os.close(fd)
            raise
        if now is not None and (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino):
            return DatabaseLock(lock, fd)
        os.close(fd)  # its holder removed that file on release: lock the one that stands now


def _identity(path: str) -> tuple[int, ...] | None:
    """What changes when a writer replaces the file at ``path`` (None when there is none)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def _keep_mode(tmp: str, path: str) -> None:
    """Give ``tmp`` the permission bits of the database it replaces (a new one keeps the umask's)."""
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except FileNotFoundError:
        return
    os.chmod(tmp, mode)
