"""The dynatex tile database: one HDF5 file holding one or more named textures.

``FORMAT.md`` beside this module documents the layout. This package alone knows it.
"""
from __future__ import annotations

__version__ = "0.1.0"

from .database import Texture, TileDB, open_db
from .errors import (MethodNotFoundError, TextureNotFoundError, TileDBError, TileDBFormatError,
                     TileDBNotFoundError, TileDBVersionError)
from .frames import FrameStore
from .lds import LDSModel
from .quilt import QuiltModel
from .mixture import MixtureModel
from .schema import FORMAT_NAME, FORMAT_VERSION
from .source import SourceInfo
from .tiles import TilesModel
from .turnpoints import TurnPointModel
from .writer import DatabaseWriter

__all__ = [
    "DatabaseWriter", "FORMAT_NAME", "FORMAT_VERSION", "FrameStore", "LDSModel", "MethodNotFoundError", "MixtureModel",
    "QuiltModel",
    "SourceInfo", "Texture", "TextureNotFoundError", "TileDB", "TileDBError", "TileDBFormatError",
    "TileDBNotFoundError", "TileDBVersionError", "TilesModel", "TurnPointModel", "open_db",
]
