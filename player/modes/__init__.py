"""The player modes by name; each entry is imported only when used.

A texture names the mode that plays it best when the analysis chose one (its ``default_mode``);
otherwise the first of :data:`MODE_ORDER` whose method it holds plays it (:func:`default_mode`).
:func:`describe` lists what a database offers: its textures, the modes that play each and
every mode's controls with their ranges and defaults (what ``dynatex info`` prints).

Examples
--------
>>> resolve_mode("quilt")      # the evolve mode plays a quilt analysis; its method's name works too
'evolve'
>>> MODE_METHOD["evolve"]
'quilt'
"""

from __future__ import annotations

import importlib
import os
from typing import Any

from ...errors import InvalidArgumentError
from ...tiledb import Texture, TileDB
from ...tiledb.database import MODE_METHOD as _MODE_METHOD
from ...tiledb.database import PLAYER_MODES

#: mode name -> "module:Class" inside dynatex.player.modes
MODES: dict[str, str] = {
    "lds": "lds:LDSPlayer",
    "tiles": "tiles:TilesPlayer",
    "turnpoints": "turnpoints:TurnPointPlayer",
    "mixture": "mixture:MixturePlayer",
    "evolve": "evolve:EvolvePlayer",
}
#: other names of a mode: the evolve mode plays what ``--methods quilt`` learned
MODE_ALIASES: dict[str, str] = {"quilt": "evolve"}
#: the analysis method each mode plays (``dynatex analyze --methods``)
MODE_METHOD: dict[str, str] = dict(_MODE_METHOD)
#: the order in which a texture holding several methods picks its default mode
MODE_ORDER: tuple[str, ...] = PLAYER_MODES


def resolve_mode(mode: str) -> str:
    """The mode ``mode`` names (a mode or an alias); an unknown name is an :class:`InvalidArgumentError`."""
    if isinstance(mode, str) and mode in MODE_ALIASES:
        return MODE_ALIASES[mode]
    if mode not in MODES:
        names = sorted(MODES) + [f"{a} (= {m})" for a, m in MODE_ALIASES.items()]
        raise InvalidArgumentError(f"mode must be one of {', '.join(names)}, not {mode!r}")
    return mode


def player_class(mode: str):
    """The player class of ``mode`` (a mode name or an alias), imported on first use."""
    module, cls = MODES[resolve_mode(mode)].split(":")
    return getattr(importlib.import_module(f"dynatex.player.modes.{module}"), cls)


def default_mode(texture: Texture) -> str:
    """The mode that plays ``texture`` when the caller names none: its ``default_mode`` attribute
    when the analysis wrote one, else the first mode of :data:`MODE_ORDER` whose method it holds."""
    if texture.default_mode is not None:
        return texture.default_mode
    modes = texture.playable_modes()
    if not modes:
        raise InvalidArgumentError(f"texture {texture.name!r} holds no method a player mode plays")
    return modes[0]


def mode_for(db: str | os.PathLike | TileDB, texture: str | None = None) -> str:
    """:func:`default_mode` of texture ``texture`` (None: the only one) of database ``db``."""
    if isinstance(db, TileDB):
        return default_mode(db.texture(texture))
    with TileDB(db) as opened:
        return default_mode(opened.texture(texture))


def mode_info(mode: str) -> dict[str, Any]:
    """What mode ``mode`` is: its method, first docstring line, options and controls (rule and default)."""
    cls = player_class(mode)

    def entry(p) -> dict[str, Any]:
        return {"rule": p.kind.describe(), "default": p.default_text(), "doc": p.doc}

    return {
        "method": cls.method,
        "summary": (cls.__doc__ or "").strip().splitlines()[0],
        "options": {p.name: entry(p) for p in cls.options},
        "controls": {name: entry(c.param) for name, c in cls.controls().items()},
    }


def describe(db: str | os.PathLike | TileDB) -> dict[str, Any]:
    """What database ``db`` offers a player: per texture its size, methods, the modes that play it
    (the default first) and per mode its options and controls with their rules and defaults.

    Parameters
    ----------
    db : str, os.PathLike or TileDB
        The tile database.

    Returns
    -------
    dict
        ``{"file", "textures": {name: {"size", "frames", "methods", "modes", "default_mode"}},
        "modes": {mode: {"method", "summary", "options", "controls"}}}``, each option and control
        as ``{"rule", "default", "doc"}``; plain values, ready for ``json.dumps``.

    Examples
    --------
    >>> from importlib import resources
    >>> d = describe(resources.files("dynatex.player").joinpath("selftest.h5"))
    >>> d["textures"]["selftest"]["modes"]
    ['lds', 'turnpoints', 'tiles', 'evolve', 'mixture']
    >>> d["modes"]["lds"]["controls"]["speed"]["rule"]
    'a finite number in [-3, 3]'
    """
    if not isinstance(db, TileDB):
        with TileDB(db) as opened:
            return describe(opened)
    textures: dict[str, Any] = {}
    for tex in db:
        s = tex.source
        modes = list(tex.playable_modes())
        if modes:
            first = default_mode(tex)
            modes = [first] + [m for m in modes if m != first]
        textures[tex.name] = {
            "size": f"{s.width}x{s.height}",
            "frames": s.n_frames,
            "methods": list(tex.methods),
            "modes": modes,
            "default_mode": modes[0] if modes else None,
        }
    used = [m for m in MODE_ORDER if any(m in t["modes"] for t in textures.values())]
    return {"file": db.filename, "textures": textures, "modes": {m: mode_info(m) for m in used}}


__all__ = [
    "MODES",
    "MODE_ALIASES",
    "MODE_METHOD",
    "MODE_ORDER",
    "default_mode",
    "describe",
    "mode_for",
    "mode_info",
    "player_class",
    "resolve_mode",
]
