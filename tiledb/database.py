"""Reading a tile database: :func:`open_db` validates on open and hands out textures."""

from __future__ import annotations

import json
import os
import unicodedata
from typing import Any

import h5py

from ..errors import InvalidArgumentError
from . import frames as _frames
from . import probe as _probe
from . import schema
from . import source as _source
from ._check import Checker, survey
from .codecs import CODECS
from .errors import (
    MethodNotFoundError,
    TextureNotFoundError,
    TileDBError,
    TileDBFormatError,
    TileDBNotFoundError,
    TileDBVersionError,
)
from .frames import FrameStore
from .source import SourceInfo

#: the player modes a texture's ``default_mode`` attribute may name (``dynatex.player.MODES``; a test holds them equal)
PLAYER_MODES = ("lds", "turnpoints", "tiles", "evolve", "mixture")
#: the analysis method each player mode plays
MODE_METHOD = {"lds": "lds", "turnpoints": "turnpoints", "tiles": "tiles", "evolve": "quilt", "mixture": "mixture"}

#: Most declared bytes one read may bring into memory (one method's model, or a whole frame store),
#: unless the caller raises it: ``TileDB(path, max_bytes=...)`` or ``DYNATEX_MAX_READ_BYTES``.
DEFAULT_MAX_BYTES = 4 * 2**30


def default_max_bytes() -> int:
    """``$DYNATEX_MAX_READ_BYTES`` when set to a positive integer, else :data:`DEFAULT_MAX_BYTES`."""
    text = os.environ.get("DYNATEX_MAX_READ_BYTES", "").strip()
    if not text:
        return DEFAULT_MAX_BYTES
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise InvalidArgumentError(f"DYNATEX_MAX_READ_BYTES must be a positive number of bytes, not {text!r}")
    return value


#: bytes of frames :meth:`TileDB.validate` reads at a time
_VALIDATE_BYTES = 64 * 2**20


class Texture:
    """One named texture of an open database: its source description and method data."""

    def __init__(self, db: TileDB, name: str, group: h5py.Group) -> None:
        self._db = db
        self.name = name
        self._group = group
        check = db._check
        self.source: SourceInfo = _source.read(check.group(group, schema.SOURCE), check)
        self.methods: tuple[str, ...] = tuple(m for m in CODECS if m in group)
        #: the mode the analysis chose to play this texture (attribute ``default_mode``), or None
        self.default_mode: str | None = self._read_default_mode(check)
        self._check_required_parts(check)
        if self.has_frames:
            self.frames()  # the frame store's structure (dtype, shape, count); its data is read lazily

    def __repr__(self) -> str:
        s = self.source
        return (
            f"<Texture {self.name!r} {s.width}x{s.height}x{s.channels} "
            f"{s.n_frames} frames, methods={list(self.methods)}>"
        )

    def _read_default_mode(self, check: Checker) -> str | None:
        mode = check.attr(self._group, "default_mode", str, None)
        if mode is None:
            return None
        where = f"{self._group.name}@default_mode"
        if mode not in PLAYER_MODES:
            check.fail(where, f"{mode!r} is not a player mode (one of {', '.join(PLAYER_MODES)})")
        if MODE_METHOD[mode] not in self.methods:
            check.fail(where, f"mode {mode!r} plays {MODE_METHOD[mode]!r} data, which the texture lacks")
        return mode

    def _check_required_parts(self, check: Checker) -> None:
        """Refuse a required part (``schema.REQUIRED_PARTS``) in a file of a major version whose
        readers do not know it: they would play the model without it."""
        version = self._db.version
        if version[0] >= schema.FORMAT_VERSION[0]:
            return
        for method in self.methods:
            for part in schema.REQUIRED_PARTS.get(method, ()):
                if part in check.group(self._group, method):
                    check.fail(
                        f"{self._group.name}/{method}/{part}",
                        f"a format {version[0]}.{version[1]} file cannot hold this part (its readers would play "
                        f"the model without it; a file with it is format {schema.FORMAT_VERSION[0]}.x)",
                    )

    @property
    def objpath(self) -> str:
        return self._group.name

    def playable_modes(self) -> tuple[str, ...]:
        """The player modes whose method this texture holds, in the order :data:`PLAYER_MODES`."""
        return tuple(m for m in PLAYER_MODES if MODE_METHOD[m] in self.methods)

    def has(self, method: str) -> bool:
        return method in self.methods

    def read(self, method: str) -> Any:
        """Read and validate the model stored for ``method`` (for example ``"lds"``)."""
        if method not in schema.METHODS:
            raise InvalidArgumentError(f"method must be one of {', '.join(schema.METHODS)}, not {method!r}")
        if method not in self.methods:
            playable = self.playable_modes()
            now = f"it plays now as --mode {' or --mode '.join(playable)}" if playable else "it holds no method"
            raise MethodNotFoundError(
                f"texture {self.name!r} has no {method!r} data ({now}; it has: {', '.join(self.methods) or 'none'}); "
                f"to add {method!r}, run `dynatex analyze CLIP -o DB --name {self.name} --methods {method}`",
                filename=self._db.filename,
                objpath=self._group.name,
            )
        check = self._db._check
        group = check.group(self._group, method)
        check.admit(group.name, check.declared_under(group.name), f"the {method} model")
        return CODECS[method].read(group, check, self.source)

    @property
    def has_frames(self) -> bool:
        return schema.FRAMES in self._group

    @property
    def ranking(self) -> list | None:
        """The modes ``dynatex analyze --methods auto`` ranked, best first (attribute ``ranking``,
        JSON), or None when the texture holds none."""
        try:
            text = self._group.attrs.get("ranking")
        except Exception as exc:  # h5py raises several types on unreadable attributes
            self._db._check.fail(self._group.name + "@ranking", f"cannot be read ({exc})")
        if text is None:
            return None
        text = text.decode("utf-8", "replace") if isinstance(text, bytes) else text
        try:
            value = json.loads(text) if isinstance(text, str) and len(text) <= 65536 else None
        except ValueError:
            value = None
        if not isinstance(value, list):
            self._db._check.fail(self._group.name + "@ranking", "is not a JSON list of at most 65536 characters")
        return value

    def frames(self) -> FrameStore:
        """The stored source frames, read lazily."""
        if not self.has_frames:
            raise MethodNotFoundError(
                f"texture {self.name!r} stores no frames", filename=self._db.filename, objpath=self._group.name
            )
        return _frames.read(self._group, schema.FRAMES, self._db._check, self.source)


class TileDB:
    """A read-only, validated tile database. Use :func:`open_db` or the constructor.

    Before the file is first read in this process, a child process reads all of it
    (:mod:`.probe`: the HDF5 library crashes or hangs on some corrupt files; a file that
    passed is remembered); ``probe=False`` skips that, for a file this process just wrote.

    Opening walks every object before any dataset is read and refuses what would read outside
    the file (external storage, virtual datasets, links other than hard links) or more than it
    holds (a dataset declaring more bytes than its storage can expand to). Each later read (one
    method's model, or a whole frame store) may bring at most ``max_bytes`` declared bytes into
    memory (default :func:`default_max_bytes`; ``math.inf`` lifts the bound), else
    :class:`~dynatex.tiledb.TileDBSizeError`.

    Examples
    --------
    >>> from dynatex.tiledb import open_db
    >>> with open_db("water.h5") as db:            # doctest: +SKIP
    ...     model = db.texture("water").read("lds")
    """

    def __init__(self, path: str | os.PathLike, *, probe: bool = True, max_bytes: float | None = None) -> None:
        self.filename = os.fspath(path)
        if max_bytes is None:
            max_bytes = default_max_bytes()
        if not max_bytes > 0:
            raise InvalidArgumentError(f"max_bytes must be positive, not {max_bytes!r}")
        self.max_bytes = max_bytes
        self._check = Checker(self.filename, max_bytes)
        if not os.path.exists(self.filename):
            raise TileDBNotFoundError("no such database file", filename=self.filename)
        if os.path.isdir(self.filename):
            raise TileDBFormatError("is a folder, not a database file", filename=self.filename)
        if probe:
            _probe.probe(self.filename, max_bytes)
        try:
            self._file = h5py.File(self.filename, "r")
        except OSError as exc:
            raise TileDBFormatError(
                f"not a readable HDF5 file, it may be truncated or corrupt ({_short(exc)})", filename=self.filename
            ) from None
        try:
            self._check.sizes = survey(self._file, self._check, os.path.getsize(self.filename))
            self._validate_root()
            self._textures: dict[str, Texture] = {}
            group = self._check.group(self._file, schema.TEXTURES)
            try:
                names = sorted(group.keys())
            except Exception as exc:
                self._check.fail(group.name, f"cannot be listed ({_short(exc)})")
            for name in names:
                problem = schema.texture_name_problem(name)
                if problem:
                    self._check.fail(f"{group.name}/{name}", f"invalid texture name: {problem}")
                self._textures[name] = Texture(self, name, self._check.group(group, name))
        except BaseException:
            self._file.close()
            raise

    def _validate_root(self) -> None:
        f = self._file
        fmt = self._check.attr(f, schema.ATTR_FORMAT, str, None)
        if fmt != schema.FORMAT_NAME:
            raise TileDBFormatError(
                f"not a dynatex tile database (format attribute is {fmt!r})", filename=self.filename, objpath="/"
            )
        major, minor = self._check.ints(f, schema.ATTR_VERSION, 2)
        self.version = (major, minor)
        if major not in schema.READ_MAJORS:
            majors = schema.READ_MAJORS
            raise TileDBVersionError(
                f"format version {major}.{minor} is not supported by this dynatex "
                f"(it reads major versions {majors[0]}-{majors[-1]}); upgrade dynatex or re-run the analysis",
                filename=self.filename,
                objpath="/",
            )

    # -- mapping-like access -------------------------------------------------
    @property
    def textures(self) -> tuple[str, ...]:
        return tuple(self._textures)

    def __contains__(self, name: object) -> bool:
        return name in self._textures

    def __iter__(self):
        return iter(self._textures.values())

    def __len__(self) -> int:
        return len(self._textures)

    def texture(self, name: str | None = None) -> Texture:
        """The texture called ``name``; ``None`` picks the only one (an error when there are several)."""
        if name is None:
            if len(self._textures) == 1:
                return next(iter(self._textures.values()))
            if not self._textures:
                raise TextureNotFoundError("holds no textures", filename=self.filename)
            raise TextureNotFoundError(
                f"holds several textures ({', '.join(self._textures)}); name one", filename=self.filename
            )
        try:
            return self._textures[unicodedata.normalize("NFC", name) if isinstance(name, str) else name]
        except KeyError:
            raise TextureNotFoundError(
                f"no texture named {name!r} (available: {', '.join(self._textures) or 'none'})",
                filename=self.filename,
                objpath=f"/{schema.TEXTURES}/{name}",
            ) from None

    def validate(self, *, every_frame: bool = False, keep_going: bool = False) -> list[TileDBError]:
        """Read and validate every method and frame store of every texture (open checks only the
        structure); the last stored frame is read, or all of them, in blocks, with ``every_frame``.

        The first error is raised, or with ``keep_going`` every part is read and the errors are
        returned (the probe child reads what a reader may read even when another part is refused).
        """
        errors: list[TileDBError] = []

        def attempt(read, *args) -> None:
            try:
                read(*args)
            except TileDBError as exc:
                if not keep_going:
                    raise
                errors.append(exc)

        for tex in self:
            for method in tex.methods:
                attempt(tex.read, method)
            if tex.has_frames:
                attempt(self._read_frames, tex, every_frame)
        return errors

    @staticmethod
    def _read_frames(tex: Texture, every_frame: bool) -> None:
        store = tex.frames()
        step = max(1, _VALIDATE_BYTES * len(store) // max(store.nbytes, 1))  # frames per read
        for i in range(0, len(store), step) if every_frame else range(len(store) - 1, len(store)):
            store[i : i + step]

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> TileDB:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<TileDB {self.filename!r} v{self.version[0]}.{self.version[1]} textures={list(self._textures)}>"


def read_everything(filename: str, max_bytes: float) -> None:
    """Open ``filename`` unprobed and read every part a reader may read, with at most ``max_bytes``
    declared bytes per read; raise the first problem found. What the probe's child process runs
    (:mod:`.probe`): a crash or hang here is the probe's verdict."""
    with TileDB(filename, probe=False, max_bytes=max_bytes) as db:
        errors = db.validate(every_frame=True, keep_going=True)
    if errors:
        raise errors[0]


def open_db(path: str | os.PathLike, *, max_bytes: float | None = None) -> TileDB:
    """Open and validate a tile database for reading.

    Parameters
    ----------
    path : str or os.PathLike
        The database file (``dynatex analyze`` writes it).
    max_bytes : float, optional
        Most declared bytes one read may bring into memory (see :class:`TileDB`).

    Returns
    -------
    TileDB
        The open database: ``textures`` names its textures, ``texture(name)`` gives one
        (``methods``, ``playable_modes()``, ``default_mode``, ``source``); close it or use ``with``.

    Raises
    ------
    TileDBError
        A missing, corrupt or foreign file (the message names the file, the object and the problem).

    Examples
    --------
    >>> from importlib import resources
    >>> with open_db(resources.files("dynatex.player").joinpath("selftest.h5")) as db:
    ...     tex = db.texture("selftest")
    ...     db.textures, tex.methods, tex.playable_modes()[:2]
    (('selftest',), ('lds', 'turnpoints', 'quilt', 'mixture', 'tiles'), ('lds', 'turnpoints'))
    """
    return TileDB(path, max_bytes=max_bytes)


def _short(exc: BaseException) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
