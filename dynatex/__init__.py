"""dynatex: endless, editable dynamic textures from short clips.

The analyzer (``dynatex.analyzer``) learns models offline and writes an HDF5 tile
database (``dynatex.tiledb``); the player (``dynatex.player``) assembles frames in real time.

The names below are loaded on first use, so ``import dynatex`` in a game imports neither the
analyzer nor OpenCV, SciPy or Dask (nor the player, until ``dynatex.open_player`` is touched).

========================  ===========================================================
``open_player``           a real-time player of one texture (:func:`dynatex.player.open_player`)
``open_db``               a validated, read-only tile database (:func:`dynatex.tiledb.open_db`)
``describe``              what a database offers: textures, their modes, each mode's controls
``analyze``               learn a clip's methods into a database (what ``dynatex analyze`` does)
``load_clip``             a clip from a video, a folder of images or an array (:func:`dynatex.analyzer.load_clip`)
``DynatexError``          the root of every error dynatex raises on purpose; its family below
========================  ===========================================================

Examples
--------
>>> import dynatex
>>> from importlib import resources
>>> db = resources.files("dynatex.player").joinpath("selftest.h5")
>>> dynatex.describe(db)["textures"]["selftest"]["default_mode"]
'lds'
>>> with dynatex.open_player(db, backend="numpy") as player:   # the texture's default mode
...     player.mode, player.next_frame().shape
('lds', (24, 32, 3))
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: public name -> module it comes from (imported when the name is first used)
_LAZY: dict[str, str] = {
    "open_player": "dynatex.player",
    "describe": "dynatex.player",
    "open_db": "dynatex.tiledb",
    "analyze": "dynatex._analyze",
    "load_clip": "dynatex.analyzer",
    "DynatexError": "dynatex.errors",
    "InvalidArgumentError": "dynatex.errors",
    "ArgumentTypeError": "dynatex.errors",
    "TileDBError": "dynatex.tiledb",
    "TileDBNotFoundError": "dynatex.tiledb",
    "TileDBFormatError": "dynatex.tiledb",
    "TileDBVersionError": "dynatex.tiledb",
    "TextureNotFoundError": "dynatex.tiledb",
    "MethodNotFoundError": "dynatex.tiledb",
    "UnknownControlError": "dynatex.player",
    "OpenCLUnavailableError": "dynatex.player",
    "DeviceNotVerifiedError": "dynatex.player",
    "KernelBuildError": "dynatex.player",
    "ClipError": "dynatex.analyzer",
}

__all__ = [
    "__version__",
    "ArgumentTypeError",
    "ClipError",
    "DeviceNotVerifiedError",
    "DynatexError",
    "InvalidArgumentError",
    "KernelBuildError",
    "MethodNotFoundError",
    "OpenCLUnavailableError",
    "TextureNotFoundError",
    "TileDBError",
    "TileDBFormatError",
    "TileDBNotFoundError",
    "TileDBVersionError",
    "UnknownControlError",
    "analyze",
    "describe",
    "load_clip",
    "open_db",
    "open_player",
]

if TYPE_CHECKING:  # what static tools see; at run time __getattr__ imports on first use
    from ._analyze import analyze
    from .analyzer import ClipError, load_clip
    from .errors import ArgumentTypeError, DynatexError, InvalidArgumentError
    from .player import (
        DeviceNotVerifiedError,
        KernelBuildError,
        OpenCLUnavailableError,
        UnknownControlError,
        describe,
        open_player,
    )
    from .tiledb import (
        MethodNotFoundError,
        TextureNotFoundError,
        TileDBError,
        TileDBFormatError,
        TileDBNotFoundError,
        TileDBVersionError,
        open_db,
    )


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'dynatex' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(__all__) | {k for k in globals() if k.startswith("__")} - {"__getattr__", "__dir__"})
