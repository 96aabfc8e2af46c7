"""Command-line options generated from what a player mode declares (its options and controls).

``dynatex play`` and ``dynatex export`` build one parser per mode: the mode named by
``--mode`` on the command line (found before parsing, :func:`mode_from_argv`) contributes
its constructor options and its controls as flags, so a flag of another mode is an
argparse usage error. A new control declared on a player class appears here, in the saved
state and in the class docstring without further code.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..player import MODES
from ..player.base import COMMON_OPTIONS
from ..player.modes import player_class
from ._common import add_param


def mode_from_argv(argv: list[str] | None, default: str) -> str:
    """The mode ``--mode M`` (or ``--mode=M``) names in ``argv``, else ``default``.

    An unknown name is returned as it is: the parser's ``choices`` then reports it.

    >>> mode_from_argv(["play", "db.h5", "--mode", "tiles"], "lds"), mode_from_argv(["play", "--mode=evolve"], "lds")
    ('tiles', 'evolve')
    """
    argv = list(argv or [])
    for i, arg in enumerate(argv):
        if arg == "--":
            break
        if arg == "--mode" and i + 1 < len(argv):
            return argv[i + 1]
        if arg.startswith("--mode="):
            return arg.split("=", 1)[1]
    return default


def add_mode_arguments(
    parser: argparse.ArgumentParser, argv: list[str] | None, *, default: str, common: tuple[str, ...]
) -> type:
    """Add ``--mode`` and, for the mode ``argv`` names (else ``default``), the ``common`` player
    parameters, the mode's options and its controls; return the mode's class.

    An unknown ``--mode`` offers the default mode's flags: the parser's ``choices`` then report it.
    """
    mode = mode_from_argv(argv, default)
    mode = mode if mode in MODES else default
    parser.add_argument(
        "--mode",
        default=default,
        choices=sorted(MODES),
        help=f"player mode (default {default}); it decides the options and controls below",
    )
    parser.epilog = (
        f"Each mode has its own options and controls; this help lists one mode's (--mode). "
        f"See them with '{parser.prog} --mode MODE --help' for MODE in: {', '.join(sorted(MODES))}."
    )
    cls = player_class(mode)
    for param in COMMON_OPTIONS:
        if param.name in common:
            add_param(parser, param)
    if cls.options:
        g = parser.add_argument_group(f"{mode} options (fixed for the run)")
        for param in cls.options:
            add_param(g, param)
    controls = [c.param for c in cls.controls().values() if c.param.flag_name]
    if controls:
        g = parser.add_argument_group(f"{mode} controls")
        for param in controls:
            add_param(g, param)
    return cls


def player_kwargs(args: argparse.Namespace, cls: type, *, common: tuple[str, ...]) -> dict[str, Any]:
    """The constructor keywords the command line gave for mode ``cls`` (common ones included)."""
    names = [p.name for p in COMMON_OPTIONS if p.name in common] + [p.name for p in cls.options]
    return {name: getattr(args, name) for name in names if hasattr(args, name)}


def apply_controls(player: Any, args: argparse.Namespace) -> None:
    """Set every control the command line gave on ``player``."""
    for name, control in player.controls().items():
        if control.param.flag_name and hasattr(args, name):
            setattr(player, name, getattr(args, name))


__all__ = ["add_mode_arguments", "apply_controls", "mode_from_argv", "player_kwargs"]
