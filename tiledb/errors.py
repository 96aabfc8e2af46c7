"""Exceptions raised by the tile database.

Every error derives from :class:`~dynatex.errors.DynatexError`, the root in the leaf module
:mod:`dynatex.errors` that every layer imports.
Callers catch :class:`TileDBError`; each subclass also derives from the builtin it
refines, so ``except FileNotFoundError`` or ``except KeyError`` work as expected.
Messages read ``FILE: OBJECT-PATH: problem``.
"""

from __future__ import annotations

import os

from ..errors import DynatexError


class TileDBError(DynatexError):
    """Base class of every tile database error."""

    def __init__(self, problem: str, *, filename: str | os.PathLike | None = None, objpath: str | None = None) -> None:
        self.problem = problem
        self.filename = os.fspath(filename) if filename is not None else None
        self.objpath = objpath
        parts = [p for p in (self.filename, objpath, problem) if p]
        Exception.__init__(self, ": ".join(parts))

    def __str__(self) -> str:  # KeyError would quote the message otherwise
        return str(self.args[0])


class TileDBNotFoundError(TileDBError, FileNotFoundError):
    """The database file does not exist."""


class TileDBFormatError(TileDBError, ValueError):
    """The file is not a valid dynatex tile database (corrupt, truncated, inconsistent)."""


class TileDBSizeError(TileDBFormatError):
    """A read would bring more declared data into memory than the reader's bound (``max_bytes``) allows."""


class TileDBVersionError(TileDBFormatError):
    """The file has a format major version this reader does not understand."""


class TextureNotFoundError(TileDBError, KeyError):
    """No texture of that name in the database."""


class MethodNotFoundError(TileDBError, KeyError):
    """The texture exists but holds no data for the requested method."""


class TileDBWriteError(TileDBError, OSError):
    """The system refused writing the database (a full disk, a quota); the database is unchanged.
    ``errno`` is the system's."""

    def __init__(self, problem: str, *, errno: int | None = None, filename: str | os.PathLike | None = None) -> None:
        super().__init__(problem, filename=filename)
        self.errno = errno
