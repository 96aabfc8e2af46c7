"""Writing a tile database atomically: a temporary file in the same folder, then a rename.

An interrupted or failed write leaves the previous database exactly as it was.
"""
from __future__ import annotations

import os
import tempfile
from typing import Any

import h5py
import numpy as np

from . import frames as _frames
from . import schema
from . import source as _source
from .codecs import CODECS
from .database import TileDB
from .errors import TextureNotFoundError
from .source import SourceInfo


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
        # Validate the existing database before touching anything.
        self._old: TileDB | None = None
        if os.path.exists(self.path) and not overwrite:
            self._old = TileDB(self.path)
        fd, self._tmp = tempfile.mkstemp(prefix=f".{os.path.basename(self.path)}.", suffix=".tmp", dir=folder)
        os.close(fd)
        self._file: h5py.File | None = h5py.File(self._tmp, "w")
        self._file.attrs[schema.ATTR_FORMAT] = schema.FORMAT_NAME
        self._file.attrs[schema.ATTR_VERSION] = np.asarray(schema.FORMAT_VERSION, np.int32)
        from . import __version__
        self._file.attrs[schema.ATTR_CREATED_BY] = f"dynatex {__version__}"
        self._textures = self._file.create_group(schema.TEXTURES)
        self._removed: set[str] = set()

    # -- textures --------------------------------------------------------------
    def put_texture(self, name: str, source: SourceInfo) -> None:
        """Create texture ``name`` afresh (replacing any texture of that name) with its source description."""
        _check_name(name)
        if name in self._textures:
            del self._textures[name]
        self._removed.add(name)  # the old file's copy is not carried over
        g = self._textures.create_group(name)
        _source.write(g.create_group(schema.SOURCE), source)

    def remove_texture(self, name: str) -> None:
        if name not in self._textures and not (self._old and name in self._old and name not in self._removed):
            raise TextureNotFoundError(f"no texture named {name!r}", filename=self.path)
        if name in self._textures:
            del self._textures[name]
        self._removed.add(name)

    def put_method(self, name: str, method: str, model: Any) -> None:
        """Store ``model`` as texture ``name``'s ``method`` group, replacing an earlier one."""
        if method not in CODECS:
            raise ValueError(f"method must be one of {sorted(CODECS)}, not {method!r}")
        g = self._texture_group(name, skip=method)
        if method in g:
            del g[method]
        CODECS[method].write(g.create_group(method), model)

    def put_frames(self, name: str, frames: np.ndarray) -> None:
        """Store the source frames texture ``name``'s gather-based methods play from."""
        g = self._texture_group(name, skip=schema.FRAMES)
        if schema.FRAMES in g:
            del g[schema.FRAMES]
        _frames.write(g, schema.FRAMES, frames)

    def source(self, name: str) -> SourceInfo:
        from ._check import Checker
        g = self._texture_group(name)
        return _source.read(g[schema.SOURCE], Checker(self._tmp))

    def _texture_group(self, name: str, skip: str | None = None) -> h5py.Group:
        if name in self._textures:
            return self._textures[name]
        if self._old is not None and name in self._old and name not in self._removed:
            old = self._old._file[schema.TEXTURES][name]
            g = self._textures.create_group(name)
            for key in old:
                if key != skip:
                    old.copy(old[key], g, name=key)
            return g
        raise TextureNotFoundError(f"no texture named {name!r}; call put_texture first", filename=self.path)

    # -- commit / abort ----------------------------------------------------------
    def commit(self) -> None:
        """Carry over untouched textures, validate the new file, and rename it onto ``path``."""
        if self._file is None:
            raise RuntimeError("writer already committed or aborted")
        try:
            if self._old is not None:
                for name in self._old.textures:
                    if name not in self._textures and name not in self._removed:
                        self._texture_group(name)
            self._file.close()
            self._file = None
            with TileDB(self._tmp) as db:
                db.validate()
            if self._old is not None:
                self._old.close()
                self._old = None
            os.replace(self._tmp, self.path)
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Discard everything written; ``path`` is left untouched."""
        if self._file is not None:
            try:
                self._file.close()
            finally:
                self._file = None
        if self._old is not None:
            self._old.close()
            self._old = None
        if os.path.exists(self._tmp):
            os.unlink(self._tmp)

    def __enter__(self) -> DatabaseWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            if self._file is not None:  # not already committed or aborted
                self.commit()
        else:
            self.abort()


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not schema.TEXTURE_NAME_RE.match(name):
        raise ValueError(f"texture name {name!r} is invalid: use 1-64 letters, digits, '_', '.', '-'")
