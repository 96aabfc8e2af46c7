"""Versioned parts of a model group: the optional ``detail`` and ``gamut`` (of ``lds`` and
``mixture``), ``switching`` (of ``mixture``) and ``flow`` (of ``turnpoints``), and the required
``tone`` (of ``lds`` and ``mixture``).

A part is a subgroup with an integer ``version`` attribute. An optional part (:func:`open_part`)
changes how a model plays, not what its values mean: a database written before the part plays
without it, and a reader that meets a newer version than it understands plays without it too (so
a newer analyzer never locks older players out). A required part (:func:`open_required_part`)
gives the model's values their meaning, so a model is garbage without it: a reader refuses a newer
version with :class:`~.errors.TileDBVersionError`, and a file holding one is of a format major
version older readers refuse (``schema.REQUIRED_PARTS``). A part of a version the reader knows is
validated like the rest of the file.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

import h5py
import numpy as np

from ._check import Checker
from .errors import TileDBVersionError


def write_part(
    parent: h5py.Group,
    name: str,
    version: int,
    datasets: Mapping[str, np.ndarray],
    *,
    attrs: Mapping[str, Any] | None = None,
    rows: Collection[str] = (),
) -> None:
    """Store ``parent/name`` at ``version``: its ``datasets`` (already of their stored dtype) and
    scalar ``attrs`` (a ``version`` among them is dropped); a dataset named in ``rows`` is chunked a
    leading-axis entry at a time, for reads of one row."""
    g = parent.create_group(name)
    g.attrs["version"] = version
    for key, value in (attrs or {}).items():
        if key != "version":
            g.attrs[key] = value
    for key, data in datasets.items():
        chunks = (1,) + data.shape[1:] if key in rows and len(data) else None
        g.create_dataset(key, data=data, chunks=chunks)


def open_part(parent: h5py.Group, name: str, version: int, check: Checker) -> h5py.Group | None:
    """The group ``parent/name`` to validate, or None when absent or newer than ``version``."""
    if name not in parent:
        return None
    g = check.group(parent, name)
    if check.attr(g, "version", int) > version:
        return None
    return g


def open_required_part(parent: h5py.Group, name: str, version: int, check: Checker) -> h5py.Group | None:
    """The group ``parent/name`` to validate, or None when absent; a version newer than ``version``
    is refused (:class:`~.errors.TileDBVersionError`): the model ``parent`` cannot play without it."""
    if name not in parent:
        return None
    g = check.group(parent, name)
    got = check.attr(g, "version", int)
    if got < 1:
        check.fail(g.name + "@version", f"{got} is not a part version (1 or more)")
    if got > version:
        model = parent.name.rstrip("/").split("/")
        what = f"the {model[-1]} model of texture {model[-2]!r}" if len(model) >= 3 else f"the model {parent.name}"
        raise TileDBVersionError(
            f"{what} needs its {name} part, of version {got}, which this dynatex does not read (it reads "
            f"up to {version}); upgrade dynatex",
            filename=check.filename,
            objpath=g.name,
        )
    return g


def exact_dtype(check: Checker, path: str, array: Any, dtype: type) -> None:
    """Refuse ``array`` (an array or an h5py dataset at ``path``) unless its dtype is ``dtype``."""
    if array.dtype != dtype:
        check.fail(path, f"dtype {array.dtype} is not {np.dtype(dtype)}")
