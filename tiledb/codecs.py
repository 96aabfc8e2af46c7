"""Which module reads and writes each method group.

A codec module has ``write(group, model)`` and ``read(group, check, source) -> model``;
``read`` validates everything it returns. Its model class describes itself:
``describe()`` (plain facts, for ``dynatex info``) and ``summary()`` (one line, for
``dynatex analyze``); see :mod:`dynatex.tiledb._describe`.
"""

from __future__ import annotations

from types import ModuleType

from . import lds, mixture, quilt, schema, tiles, turnpoints

CODECS: dict[str, ModuleType] = {
    schema.METHOD_LDS: lds,
    schema.METHOD_TURNPOINTS: turnpoints,
    schema.METHOD_QUILT: quilt,
    schema.METHOD_MIXTURE: mixture,
    schema.METHOD_TILES: tiles,
}
