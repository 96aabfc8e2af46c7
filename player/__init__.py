"""The real-time player: opens a tile database and assembles frames with OpenCL.

Imports only numpy, h5py and pyopencl (a game ships the player and a database, nothing else).

Examples
--------
>>> from dynatex.player import open_player
>>> with open_player("water.h5", mode="lds", seed=1) as p:     # doctest: +SKIP
...     frame = p.next_frame()                                 # (H, W, 3) uint8
"""

from __future__ import annotations

import os

from .base import BACKENDS, Player, PlayerClosedError, PlayerForkedError
from .modes import MODES, player_class
from .opencl import DeviceNotVerifiedError, KernelBuildError, OpenCLUnavailableError, devices, list_devices


def open_player(db: str | os.PathLike, texture: str | None = None, *, mode: str = "lds", **options) -> Player:
    """Open a player of ``mode`` for ``texture`` of database ``db``; ``options`` go to the mode's class."""
    return player_class(mode)(db, texture, **options)


__all__ = [
    "BACKENDS",
    "DeviceNotVerifiedError",
    "KernelBuildError",
    "MODES",
    "OpenCLUnavailableError",
    "Player",
    "PlayerClosedError",
    "PlayerForkedError",
    "devices",
    "list_devices",
    "open_player",
    "player_class",
]
