"""Write ``player/MODES.md`` from the player modes' declarations (tests/player/test_controls.py checks it)."""

from __future__ import annotations

import pathlib

from dynatex.player.base import COMMON_OPTIONS
from dynatex.player.controls import markdown
from dynatex.player.modes import MODES, player_class

PATH = pathlib.Path(__file__).resolve().parent.parent / "player" / "MODES.md"


def text() -> str:
    return markdown([player_class(m) for m in MODES], COMMON_OPTIONS)


if __name__ == "__main__":
    PATH.write_text(text(), encoding="utf-8")
    print(f"wrote {PATH}")
