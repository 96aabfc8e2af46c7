"""Files and folders that killed runs left behind, found by name and removed when no live run holds them.

One rule for every kind of scratch a run leaves (a writer's temporary database, a decode folder,
a spill file): a live run keeps a shared ``flock`` on its own (:func:`hold`), so an exclusive one
is granted on stale ones alone (:func:`remove_unheld`). Locks die with their process, so a crash
never makes a live entry look stale or a stale one live. Without ``fcntl`` (Windows) nothing is
held or removed: nothing can tell live from stale.
"""

from __future__ import annotations

import os
import re
import shutil

try:
    import fcntl
except ImportError:  # pragma: no cover (not POSIX)
    fcntl = None  # type: ignore[assignment]

__all__ = ["hold", "release", "remove_unheld"]


def hold(path: str) -> int | None:
    """A descriptor holding a shared ``flock`` on this run's file or folder ``path`` while the run
    lives (:func:`release` lets go), so that :func:`remove_unheld` of another run leaves it alone;
    None when a cleaner removed ``path`` between its creation and now (make another); -1 without
    ``fcntl`` (nothing held: an open descriptor there would only stop a rename)."""
    if fcntl is None:
        return -1
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        return None
    fcntl.flock(fd, fcntl.LOCK_SH)
    try:
        now = os.lstat(path)
    except FileNotFoundError:
        now = None
    held = os.fstat(fd)
    if now is None or (now.st_dev, now.st_ino) != (held.st_dev, held.st_ino):
        os.close(fd)
        return None
    return fd


def release(fd: int | None) -> None:
    """Let go of what :func:`hold` holds (None and -1: nothing)."""
    if fd is not None and fd >= 0:
        os.close(fd)


def remove_unheld(folder: str, pattern: re.Pattern[str], *, folders: bool = False) -> list[str]:
    """Remove the entries of ``folder`` whose names ``pattern`` matches in full and that no live run
    holds (files, and folders too with ``folders``; never a symbolic link); returns their paths.

    >>> import tempfile
    >>> d = tempfile.mkdtemp()
    >>> open(os.path.join(d, "x.tmp"), "w").close()
    >>> [os.path.basename(p) for p in remove_unheld(d, re.compile(r"x\\.tmp"))], os.listdir(d)
    (['x.tmp'], [])
    """
    if fcntl is None:
        return []
    removed = []
    try:
        entries = [e for e in os.scandir(folder) if pattern.fullmatch(e.name)]
    except OSError:
        return []
    for entry in entries:
        try:
            is_dir = entry.is_dir(follow_symlinks=False)
            if entry.is_symlink() or (is_dir and not folders):
                continue
            fd = os.open(entry.path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            held, now = os.fstat(fd), os.lstat(entry.path)
            if (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino):
                shutil.rmtree(entry.path) if is_dir else os.unlink(entry.path)
                removed.append(entry.path)
        except OSError:  # held by a live run (BlockingIOError), gone, or not ours to remove
            pass
        finally:
            os.close(fd)
    return removed
