"""dynatex: endless, editable dynamic textures from short clips.

The analyzer (``dynatex.analyzer``) learns models offline and writes an HDF5 tile
database (``dynatex.tiledb``); the player (``dynatex.player``) assembles frames in real time.
"""

from __future__ import annotations

__version__ = "0.1.0"
