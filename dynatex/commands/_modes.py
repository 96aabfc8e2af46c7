"""Command-line options generated from what a player mode declares (its options and controls).

``dynatex play`` and ``dynatex export`` build one parser per mode: the mode named by
``--mode`` on the command line (found before parsing, :func:`mode_from_argv`) contributes
its constructor options and its controls as flags, so a flag of another mode is an
argparse usage error. A new control declared on a player class appears here, in the saved
state and in the class docstring without further code.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from ..errors import DynatexError
from ..player import MODES
from ..player.base import COMMON_OPTIONS
from ..player.modes import MODE_ALIASES, MODE_ORDER, mode_for, player_class
from ._common import add_param

#: the mode whose flags a command offers when it cannot read the texture to choose one
FALLBACK_MODE = "lds"
_DEFAULT_HELP = (
    "the texture's: the mode its analysis chose, else the first of " + ", ".join(MODE_ORDER) + " whose method it holds"
)


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


def mode_name(text: str) -> str:
    """``--mode``'s type: a mode's alias becomes the mode (``quilt`` -> ``evolve``); anything else
    stays as it is, for the parser's ``choices`` to report."""
    return MODE_ALIASES.get(text, text)


def guess_mode(argv: list[str] | None, command: str) -> str | None:
    """The mode that plays the texture the command line names, when ``--mode`` is not given: the
    first argument after ``command`` that is an HDF5 file is the database, ``--texture`` its
    texture (see :func:`dynatex.player.modes.default_mode`); None when they cannot be read (the
    command then reports why)."""
    argv = list(argv or [])
    rest = argv[argv.index(command) + 1 :] if command in argv else argv
    texture = None
    database = None
    for i, arg in enumerate(rest):
        if arg == "--":
            break
        if arg == "--texture" and i + 1 < len(rest):
            texture = rest[i + 1]
        elif arg.startswith("--texture="):
            texture = arg.split("=", 1)[1]
        elif database is None and not arg.startswith("-") and os.path.isfile(arg):
            import h5py

            if h5py.is_hdf5(arg):
                database = arg
    if database is None:
        return None
    try:
        return mode_for(database, texture)
    except (DynatexError, OSError):
        return None


def add_mode_arguments(
    parser: argparse.ArgumentParser, argv: list[str] | None, *, default: str | None, common: tuple[str, ...]
) -> type:
    """Add ``--mode`` and, for the mode ``argv`` names, the ``common`` player parameters, the
    mode's options and its controls; return the mode's class.

    Without ``--mode`` the mode is ``default``, or with ``default=None`` the one that plays the
    texture the command line names (:func:`guess_mode`; ``lds``'s flags when it cannot be read).
    An unknown ``--mode`` offers lds's flags: the parser's ``choices`` then report it.
    """
    command = parser.prog.split()[-1]
    named = mode_from_argv(argv, None)
    guessed = guess_mode(argv, command) if named is None and default is None else None
    chosen = default if default is not None else guessed
    mode = mode_name(named) if named is not None else chosen
    mode = mode if mode in MODES else FALLBACK_MODE
    parser.add_argument(
        "--mode",
        type=mode_name,
        default=chosen,
        choices=sorted(MODES),
        help=f"player mode (default: {default or _DEFAULT_HELP}); it decides the options and controls below; "
        f"{', '.join(f'{a} is an alias of {m}' for a, m in MODE_ALIASES.items())}",
    )
    parser.epilog = (
        f"Each mode has its own options and controls; this help lists mode {mode}'s. "
        f"See another's with '{parser.prog} --mode MODE --help' for MODE in: {', '.join(sorted(MODES))}."
    )
    if named is not None or chosen is not None:  # a usage error points to the page of the mode in use
        parser.help_command = f"{parser.prog} --mode {mode} --help"
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


def resolve_args_mode(args: argparse.Namespace) -> str:
    """``args.mode``, or when the command line named none and :func:`guess_mode` could not read the
    database, the texture's mode (raising the database's own error, which says why)."""
    if args.mode is None:
        args.mode = mode_for(args.database, args.texture)
    return args.mode


def player_kwargs(args: argparse.Namespace, cls: type, *, common: tuple[str, ...]) -> dict[str, Any]:
    """The constructor keywords the command line gave for mode ``cls`` (common ones included)."""
    names = [p.name for p in COMMON_OPTIONS if p.name in common] + [p.name for p in cls.options]
    return {name: getattr(args, name) for name in names if hasattr(args, name)}


def known_count(cls: type, opts: dict[str, Any]) -> dict[str, Any]:
    """``opts`` with each option of mode ``cls`` that declares a value for commands rendering a
    known number of frames (``Param.extra["known_count"]``: the projection modes' ``lookahead``)
    set to it where the command line left it unset."""
    for p in cls.options:
        if "known_count" in p.extra and opts.get(p.name) is None:
            opts[p.name] = p.extra["known_count"]
    return opts


def apply_controls(player: Any, args: argparse.Namespace) -> None:
    """Set every control the command line gave on ``player`` (one its texture does not offer is refused)."""
    for name, control in type(player).controls().items():
        if control.param.flag_name and hasattr(args, name):
            setattr(player, name, getattr(args, name))


__all__ = [
    "add_mode_arguments",
    "apply_controls",
    "guess_mode",
    "known_count",
    "mode_from_argv",
    "mode_name",
    "player_kwargs",
    "resolve_args_mode",
]
