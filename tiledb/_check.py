"""Validation helpers shared by the readers: every failure names the file and object."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import h5py
import numpy as np

from .errors import TileDBFormatError
from .schema import MAX_ELEMENTS

_KINDS = {"f": "floating point", "i": "signed integer", "u": "unsigned integer", "iu": "integer", "S": "string"}
#: the dtypes a dataset of each kind may have: float16 has too little range and precision for
#: a model (and linear algebra refuses it), longer floats and complex numbers are not ours
_ALLOWED = {"f": {"f4", "f8"}, "i": {"i1", "i2", "i4", "i8"}, "u": {"u1", "u2", "u4", "u8"}}


class Checker:
    """Reads objects out of an open HDF5 file and raises :class:`TileDBFormatError` on any defect."""

    def __init__(self, filename: str) -> None:
        self.filename = filename

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
        shape: Sequence[int | None],
        finite: bool = True,
        read: bool = True,
    ) -> Any:
        """Check dtype kind and shape (``None`` = any length), then read the array.

        With ``read=False`` the h5py dataset itself is returned (for lazy, chunked access).
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
            if want is not None and got != want:
                self.fail(path, f"has shape {dshape}, expected {tuple(shape)}")
        if int(np.prod(dshape, dtype=np.int64)) > MAX_ELEMENTS:
            self.fail(path, f"declares an implausible shape {dshape}")
        if not read:
            return obj
        try:
            arr = obj[()]
        except Exception as exc:
            self.fail(path, f"data cannot be read, the file may be truncated or corrupt ({exc})")
        if finite and arr.dtype.kind == "f" and not np.isfinite(arr).all():
            self.fail(path, "contains NaN or infinite values")
        return arr

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


def _join(parent: str, name: str) -> str:
    return parent.rstrip("/") + "/" + name
