"""Validation helpers shared by the readers: every failure names the file and object."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import h5py
import numpy as np

from .errors import TileDBFormatError, TileDBSizeError
from .schema import MAX_ELEMENTS, MAX_OBJECTS

_KINDS = {"f": "floating point", "i": "signed integer", "u": "unsigned integer", "iu": "integer", "S": "string"}
#: the dtypes a dataset of each kind may have: float16 has too little range and precision for
#: a model (and linear algebra refuses it), longer floats and complex numbers are not ours
_ALLOWED = {"f": {"f4", "f8"}, "i": {"i1", "i2", "i4", "i8"}, "u": {"u1", "u2", "u4", "u8"}}

#: filters a dataset may use (HDF5 filter id -> name); a filter outside this table would make
#: HDF5 look for a plugin (a shared library) to load
FILTERS = {1: "deflate", 2: "shuffle", 3: "fletcher32", 32000: "lzf"}
#: the compressing ones among them
_COMPRESSING = {1, 32000}
#: most declared bytes a compressed dataset may hold per stored byte: LZF, the writer's filter,
#: reaches 89:1 on constant data; deflate reaches 1032:1 there, past any real model or frame
MAX_RATIO = 128
_LAYOUTS = {h5py.h5d.COMPACT, h5py.h5d.CONTIGUOUS, h5py.h5d.CHUNKED}  # all inside the file


class Checker:
    """Reads objects out of an open HDF5 file and raises :class:`TileDBFormatError` on any defect."""

    def __init__(self, filename: str, max_bytes: float = float("inf")) -> None:
        self.filename = filename
        self.max_bytes = max_bytes
        self.sizes: dict[str, int] = {}  # declared bytes of each dataset, by path (see :func:`survey`)

    def fail(self, objpath: str, problem: str) -> None:
        raise TileDBFormatError(problem, filename=self.filename, objpath=objpath)

    def group(self, parent: h5py.Group, name: str) -> h5py.Group:
        path = _join(parent.name, name)
        try:
            obj = parent.get(name)
        except Exception as exc:  # h5py raises KeyError/OSError/RuntimeError on damaged links
            self.fail(path, f"cannot be read ({exc})")
        if obj is None:
            self.fail(path, "missing group")
        if not isinstance(obj, h5py.Group):
            self.fail(path, "expected a group")
        return obj

    def dataset(
        self,
        parent: h5py.Group,
        name: str,
        *,
        kind: str,
        shape: Sequence[int | range],
        finite: bool = True,
        read: bool = True,
    ) -> Any:
        """Check dtype kind and shape, then read the array.

        Each entry of ``shape`` is the length of that axis, or the ``range`` of lengths the role
        allows (derived from the geometry the data describes, so that no dataset declares more
        than its role needs). With ``read=False`` the h5py dataset itself is returned (for lazy,
        chunked access).
        """
        path = _join(parent.name, name)
        try:
            obj = parent.get(name)
        except Exception as exc:
            self.fail(path, f"cannot be read ({exc})")
        if obj is None:
            self.fail(path, "missing dataset")
        if not isinstance(obj, h5py.Dataset):
            self.fail(path, "expected a dataset")
        try:
            dt = obj.dtype
            dshape = obj.shape
        except Exception as exc:
            self.fail(path, f"cannot be read ({exc})")
        if dt.kind not in kind or (dt.kind in _ALLOWED and f"{dt.kind}{dt.itemsize}" not in _ALLOWED[dt.kind]):
            self.fail(
                path, f"dtype {dt} is not {_KINDS.get(kind, kind)}" + (" of 32 or 64 bits" if kind == "f" else "")
            )
        if dshape is None or len(dshape) != len(shape):
            self.fail(path, f"has shape {dshape}, expected {len(shape)} dimensions")
        for got, want in zip(dshape, shape):
            if got not in want if isinstance(want, range) else got != want:
                expected = ", ".join(f"{w.start}..{w.stop - 1}" if isinstance(w, range) else str(w) for w in shape)
                self.fail(path, f"has shape {dshape}, expected ({expected})")
        if int(np.prod(dshape, dtype=np.int64)) > MAX_ELEMENTS:
            self.fail(path, f"declares an implausible shape {dshape}")
        if not read:
            return obj
        try:
            arr = obj[()]
        except MemoryError:  # out of memory is no defect of the file
            raise
        except Exception as exc:
            self.fail(path, f"data cannot be read, the file may be truncated or corrupt ({exc})")
        if finite and arr.dtype.kind == "f" and not np.isfinite(arr).all():
            self.fail(path, "contains NaN or infinite values")
        return arr

    def admit(self, objpath: str, need: int, what: str) -> None:
        """Refuse a read of ``need`` declared bytes above the bound, before anything is read."""
        if need > self.max_bytes:
            raise TileDBSizeError(
                f"reading {what} needs {_mib(need)} MiB, more than the bound of {_mib(self.max_bytes)} MiB "
                "(raise it with TileDB(path, max_bytes=...) or DYNATEX_MAX_READ_BYTES)",
                filename=self.filename,
                objpath=objpath,
            )

    def declared_under(self, objpath: str) -> int:
        """Declared bytes of every dataset at or below ``objpath``."""
        prefix = objpath.rstrip("/") + "/"
        return sum(n for path, n in self.sizes.items() if path == objpath or path.startswith(prefix))

    def attr(self, obj: h5py.HLObject, name: str, kind: type, default: Any = ...) -> Any:
        """Read attribute ``name`` as ``kind`` (int, float, str, bool); :meth:`ints` reads integer arrays."""
        path = f"{obj.name}@{name}"
        try:
            present = name in obj.attrs
            value = obj.attrs[name] if present else None
        except Exception as exc:
            self.fail(path, f"cannot be read ({exc})")
        if not present:
            if default is ...:
                self.fail(path, "missing attribute")
            return default
        try:
            if kind is str:
                if isinstance(value, bytes):
                    value = value.decode("utf-8")
                if not isinstance(value, str):
                    raise TypeError(type(value).__name__)
                return value
            arr = np.asarray(value)
            if arr.ndim != 0:
                raise TypeError(f"expected a scalar, got shape {arr.shape}")
            if kind is int:
                if arr.dtype.kind not in "iub":
                    raise TypeError(f"expected an integer, got {arr.dtype}")
                return int(arr)
            if kind is float:
                if arr.dtype.kind not in "iuf":
                    raise TypeError(f"expected a number, got {arr.dtype}")
                out = float(arr)
                if not np.isfinite(out):
                    raise ValueError("not finite")
                return out
            if kind is bool:
                return bool(arr)
        except (TypeError, ValueError, UnicodeDecodeError) as exc:
            self.fail(path, f"has an invalid value ({exc})")
        raise TypeError(f"unsupported attribute kind {kind!r}")

    def ints(
        self,
        obj: h5py.HLObject,
        name: str,
        length: int,
        default: tuple[int, ...] | None = None,
    ) -> tuple[int, ...]:
        """Attribute ``name`` as ``length`` integers (an integer array of that length)."""
        path = f"{obj.name}@{name}"
        try:
            present = name in obj.attrs
            value = np.asarray(obj.attrs[name]) if present else None
        except Exception as exc:
            self.fail(path, f"cannot be read ({exc})")
        if not present:
            if default is None:
                self.fail(path, "missing attribute")
            return default
        if value.dtype.kind not in "iu" or value.shape != (length,):
            self.fail(
                path, f"has an invalid value (expected {length} integers, got {value.dtype} of shape {value.shape})"
            )
        return tuple(int(v) for v in value)

    def info(self, group: h5py.Group, skip: Sequence[str] = ()) -> dict[str, Any]:
        """Every attribute of ``group`` (but ``skip``) as plain Python values: a model's ``info``.

        Numbers, strings and arrays of them become ``int``/``float``/``bool``/``str`` and lists
        (bytes decoded as UTF-8, bad bytes replaced), so ``dynatex info --json`` can print any
        file; other types (complex, compound, references) are refused.
        """
        try:
            items = [(key, v) for key, v in group.attrs.items() if key not in skip]
        except Exception as exc:
            self.fail(group.name, f"attributes cannot be read ({exc})")
        return {key: self._plain(f"{group.name}@{key}", v) for key, v in items}

    def _plain(self, path: str, value: Any) -> Any:
        if isinstance(value, (bytes, np.bytes_)):
            return bytes(value).decode("utf-8", "replace")
        if isinstance(value, str):
            return value
        arr = np.asarray(value)
        if arr.dtype.kind in "SO" and arr.ndim:
            return [self._plain(path, v) for v in arr.ravel()]
        if arr.dtype.kind not in "biufU":
            self.fail(path, f"has an unsupported type {arr.dtype}")
        return arr.tolist() if arr.ndim else arr.item()

    def index_range(self, path: str, arr: np.ndarray, stop: int) -> None:
        """Every integer in ``arr`` must lie in ``[0, stop)``."""
        if arr.size and (arr.min() < 0 or arr.max() >= stop):
            self.fail(path, f"holds indices outside [0, {stop})")


def survey(file: h5py.File, check: Checker, file_size: int) -> dict[str, int]:
    """Walk every object of ``file`` without following a link or reading a dataset, and return the
    declared bytes of each dataset by path; :class:`TileDBFormatError` names the first object that
    would make a read leave the file or outgrow it.

    Refused: links other than hard links (soft, external, user-defined), a second link to one
    object (cycles included), objects other than groups and datasets, external storage, virtual
    datasets, filters outside :data:`FILTERS`, more than :data:`~.schema.MAX_OBJECTS` objects,
    and datasets whose declared size exceeds what their stored bytes can hold: more stored bytes
    than the file has, none at all (a sparse dataset, never written), or more than
    :data:`MAX_RATIO` declared bytes per stored byte (a compression bomb; without a compressing
    filter no more than are stored). Attributes are checked against the file size too.
    """
    sizes: dict[str, int] = {}
    seen: set[tuple[int, int]] = set()
    root = h5py.h5g.open(file.id, b"/")
    stack: list[tuple[str, h5py.h5g.GroupID]] = [("/", root)]
    count = 0
    while stack:
        path, gid = stack.pop()
        _attributes(gid, path, check, file_size)
        try:
            names = list(gid)
        except Exception as exc:  # noqa: BLE001 - h5py's errors on damaged link tables vary
            check.fail(path, f"cannot be listed ({_first_line(exc)})")
        for raw in names:
            count += 1
            child = _join(path, raw.decode("utf-8", "replace"))
            if count > MAX_OBJECTS:
                check.fail(child, f"the file holds more than {MAX_OBJECTS} objects")
            try:
                kind = gid.links.get_info(raw).type
            except Exception as exc:  # noqa: BLE001
                check.fail(child, f"cannot be read ({_first_line(exc)})")
            if kind != h5py.h5l.TYPE_HARD:
                what = {h5py.h5l.TYPE_SOFT: "a soft link", h5py.h5l.TYPE_EXTERNAL: "an external link"}
                check.fail(
                    child,
                    f"is {what.get(kind, f'a user-defined link (type {kind})')}: a database holds only "
                    "its own groups and datasets",
                )
            try:
                oid = h5py.h5o.open(gid, raw)
                info = h5py.h5o.get_info(oid)
            except Exception as exc:  # noqa: BLE001
                check.fail(child, f"cannot be read ({_first_line(exc)})")
            if (info.fileno, info.addr) in seen:
                check.fail(child, "is a second link to an object met before: every object has one place")
            seen.add((info.fileno, info.addr))
            if isinstance(oid, h5py.h5g.GroupID):
                stack.append((child, oid))
            elif isinstance(oid, h5py.h5d.DatasetID):
                _attributes(oid, child, check, file_size)
                sizes[child] = _dataset(oid, child, check, file_size)
            else:
                check.fail(child, f"is a {type(oid).__name__}: a database holds only groups and datasets")
    return sizes


def _dataset(dsid: h5py.h5d.DatasetID, path: str, check: Checker, file_size: int) -> int:
    """The declared bytes of a dataset whose data lies inside the file and fits it."""
    try:
        plist = dsid.get_create_plist()
        layout = plist.get_layout()
        external = plist.get_external_count() if layout == h5py.h5d.CONTIGUOUS else 0
        filters = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
        shape = dsid.shape
        itemsize = dsid.get_type().get_size()
    except Exception as exc:  # noqa: BLE001
        check.fail(path, f"cannot be read ({_first_line(exc)})")
    if layout == h5py.h5d.VIRTUAL:
        check.fail(path, "is a virtual dataset (it maps other files' data): a database reads only itself")
    if external:
        check.fail(path, "keeps its data in external files: a database reads only itself")
    if layout not in _LAYOUTS:
        check.fail(path, f"has an unknown storage layout ({layout})")
    unknown = [f for f in filters if f not in FILTERS]
    if unknown:
        check.fail(path, f"uses the HDF5 filter {unknown[0]}, not one of {', '.join(sorted(FILTERS.values()))}")
    declared = int(np.prod(shape, dtype=object)) * int(itemsize) if shape is not None else int(itemsize)
    if not declared:
        return 0
    try:
        stored = int(dsid.get_storage_size())
    except Exception as exc:  # noqa: BLE001
        check.fail(path, f"cannot be read ({_first_line(exc)})")
    ratio = MAX_RATIO if _COMPRESSING.intersection(filters) else 1
    if stored > file_size:
        check.fail(path, f"claims {stored} stored bytes, more than the file's {file_size}")
    if stored == 0:
        check.fail(path, f"declares {declared} bytes and stores none (a sparse dataset): a database stores its data")
    if declared > stored * ratio:
        check.fail(
            path,
            f"declares {declared} bytes in {stored} stored, "
            + (f"more than {MAX_RATIO}:1 (a compression bomb)" if ratio > 1 else "more than it holds"),
        )
    return declared


def _attributes(oid: h5py.h5o.ObjectID, path: str, check: Checker, file_size: int) -> None:
    """Every attribute of an object declares no more bytes than the file holds (attributes are never compressed)."""
    try:
        n = h5py.h5o.get_info(oid).num_attrs
        if n > MAX_OBJECTS:
            check.fail(path, f"holds {n} attributes, more than {MAX_OBJECTS}")
        for i in range(n):
            aid = h5py.h5a.open(oid, index=i)
            shape = aid.shape
            declared = (int(np.prod(shape, dtype=object)) if shape else 1) * aid.get_type().get_size()
            if declared > file_size:
                name = aid.name.decode("utf-8", "replace")
                check.fail(f"{path}@{name}", f"declares {declared} bytes, more than the file's {file_size}")
    except TileDBFormatError:
        raise
    except Exception as exc:  # noqa: BLE001
        check.fail(path, f"attributes cannot be read ({_first_line(exc)})")


def _mib(n: float) -> str:
    return f"{n / 2**20:.1f}"


def _first_line(exc: BaseException) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def _join(parent: str, name: str) -> str:
    return parent.rstrip("/") + "/" + name
