"""The player modes by name; each entry is imported only when used."""

from __future__ import annotations

import importlib

from ..errors import InvalidArgumentError

#: mode name -> "module:Class" inside dynatex.player
MODES: dict[str, str] = {
    "lds": "lds:LDSPlayer",
    "tiles": "tiles:TilesPlayer",
    "turnpoints": "turnpoints:TurnPointPlayer",
    "mixture": "mixture:MixturePlayer",
    "evolve": "quilt:EvolvePlayer",
}


def player_class(mode: str):
    if mode not in MODES:
        raise InvalidArgumentError(f"mode must be one of {sorted(MODES)}, not {mode!r}")
    module, cls = MODES[mode].split(":")
    return getattr(importlib.import_module(f"dynatex.player.{module}"), cls)
