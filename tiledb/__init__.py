"""The dynatex tile database: one HDF5 file holding one or more named textures.

``FORMAT.md`` beside this module documents the layout. This package alone knows it.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("dynatex")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "unknown"

from .database import Texture, TileDB, open_db
from .errors import (
    DynatexError,
    MethodNotFoundError,
    TextureNotFoundError,
    TileDBError,
    TileDBFormatError,
    TileDBNotFoundError,
    TileDBSizeError,
    TileDBVersionError,
    TileDBWriteError,
)
from .frames import FrameStore
from .lds import LDSModel
from .mixture import MixtureModel, ResidualProcess, SwitchingDynamics
from .quilt import QuiltModel
from .schema import FORMAT_NAME, FORMAT_VERSION
from .source import SourceInfo
from .tiles import TilesModel
from .tone import ToneModel
from .turnpoints import TurnPointModel
from .writer import DatabaseWriter

__all__ = [
    "DatabaseWriter",
    "DynatexError",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "FrameStore",
    "LDSModel",
    "MethodNotFoundError",
    "MixtureModel",
    "QuiltModel",
    "ResidualProcess",
    "SourceInfo",
    "SwitchingDynamics",
    "Texture",
    "TextureNotFoundError",
    "TileDB",
    "TileDBError",
    "TileDBFormatError",
    "TileDBNotFoundError",
    "TileDBSizeError",
    "TileDBVersionError",
    "TileDBWriteError",
    "TilesModel",
    "ToneModel",
    "TurnPointModel",
    "open_db",
]
