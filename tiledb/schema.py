"""Names and versions of the tile database layout, in one place.

Only the :mod:`dynatex.tiledb` package uses these; every other part of dynatex goes
through its API. ``FORMAT.md`` beside this file documents what they mean.
"""
from __future__ import annotations

import re

FORMAT_NAME = "dynatex-tiledb"
#: (major, minor). A reader refuses another major and accepts any minor.
FORMAT_VERSION = (1, 1)

# Root attributes.
ATTR_FORMAT = "format"
ATTR_VERSION = "format_version"
ATTR_CREATED_BY = "created_by"

# Groups.
TEXTURES = "textures"
SOURCE = "source"
FRAMES = "frames"

#: Method groups a texture may hold, in the order ``dynatex info`` lists them.
METHOD_LDS = "lds"
METHOD_TURNPOINTS = "turnpoints"
METHOD_TILES = "tiles"
METHOD_QUILT = "quilt"
METHOD_MIXTURE = "mixture"
METHODS = (METHOD_LDS, METHOD_TURNPOINTS, METHOD_TILES, METHOD_QUILT, METHOD_MIXTURE)

TEXTURE_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,63}$")

#: Largest dimension any stored array may declare; guards hostile files.
MAX_ELEMENTS = 2**34
