"""The real-time player: opens a tile database and assembles frames with OpenCL.

Imports only numpy, h5py and pyopencl (a game ships the player and a database, nothing else).

Examples
--------
>>> from dynatex.player import open_player
>>> with open_player("water.h5", seed=1) as p:     # doctest: +SKIP
...     frame = p.next_frame()                     # (H, W, 3) uint8
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

from ..tiledb import TileDB
from .base import BACKENDS, Player
from .errors import (
    DeviceNotVerifiedError,
    KernelBuildError,
    OpenCLUnavailableError,
    PlayerClosedError,
    PlayerForkedError,
    UnknownControlError,
)
from .modes import MODE_ALIASES, MODE_METHOD, MODE_ORDER, MODES, default_mode, describe, mode_for, player_class

if TYPE_CHECKING:  # what static tools see; at run time __getattr__ imports on first use
    from .opencl.devices import devices, list_devices

#: the names loaded with the OpenCL plumbing, on first use
_OPENCL = ("devices", "list_devices")


def open_player(
    db: str | os.PathLike | TileDB, texture: str | None = None, *, mode: str | None = None, **options
) -> Player:
    """Open a player for one texture of a tile database.

    Parameters
    ----------
    db : str, os.PathLike or TileDB
        The tile database (``dynatex analyze`` writes it).
    texture : str, optional
        The texture's name; None picks the database's only texture.
    mode : str, optional
        The player mode: ``lds``, ``turnpoints``, ``tiles``, ``evolve`` (alias ``quilt``: it plays
        a quilt analysis) or ``mixture``. None picks the texture's own: the mode its analysis
        chose (``default_mode``), else the first of lds, turnpoints, tiles, evolve, mixture
        whose method the texture holds (:func:`dynatex.player.modes.default_mode`).
    **options
        The mode's options (``seed``, ``backend``, ``device``, ``format`` for every mode; see
        ``player/MODES.md``). Sizes are ``(height, width)``, like a frame's shape:
        ``size=(1080, 1920)`` is a landscape HD frame.

    Returns
    -------
    Player
        The open player: ``next_frame()`` gives ``(H, W, 3)`` uint8 frames, its controls are
        attributes (``type(player).controls()``), ``close()`` or a ``with`` block releases it.

    Raises
    ------
    dynatex.errors.ArgumentTypeError
        An option the mode does not take (the message names the mode's options).
    dynatex.tiledb.MethodNotFoundError
        The texture lacks the mode's method (the message names the modes it can play).

    Examples
    --------
    >>> from importlib import resources
    >>> db = resources.files("dynatex.player").joinpath("selftest.h5")
    >>> with open_player(db, mode="tiles", size=(24, 40), backend="numpy") as p:
    ...     p.next_frame().shape
    (24, 40, 3)
    >>> open_player(db, mode="lds", size=(24, 40))
    Traceback (most recent call last):
    ...
    dynatex.errors.ArgumentTypeError: mode 'lds' takes no option 'size' (it plays at the size its model fixes; ...
    """
    if mode is None:
        mode = mode_for(db, texture)
    return player_class(mode)(db, texture, **options)


def __getattr__(name: str) -> Any:
    """``devices`` and ``list_devices`` load the OpenCL plumbing (and pyopencl) on first use, so that
    what needs no device (``dynatex info``, the modes' declarations) loads none."""
    if name not in _OPENCL:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from .opencl import devices as _devices

    value = getattr(_devices, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_OPENCL))


__all__ = [
    "BACKENDS",
    "DeviceNotVerifiedError",
    "KernelBuildError",
    "MODES",
    "MODE_ALIASES",
    "MODE_METHOD",
    "MODE_ORDER",
    "OpenCLUnavailableError",
    "Player",
    "PlayerClosedError",
    "PlayerForkedError",
    "UnknownControlError",
    "default_mode",
    "describe",
    "devices",
    "list_devices",
    "mode_for",
    "open_player",
    "player_class",
]
