"""Argument types and helpers shared by the subcommands.

An option's value is parsed by a kind of :mod:`dynatex.checks` (:class:`KindArg` adapts any
kind to argparse; :class:`Number` is a range read from text) that declares its rule once: the
same object checks the value (finite, in range, before any work starts) and says the rule in
the option's help. :func:`add_param` turns a declared :class:`~dynatex.params.Param` into its option.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from .. import checks
from ..checks import MAX_COUNT, MAX_SEED, MAX_SIDE, Choice, Flag, Kind, Range, Size
from ..errors import InvalidArgumentError, UsageError
from ..params import Param


class Number(Range):
    """An argparse type: a :class:`~dynatex.checks.Range` read from command-line text.

    ``Number(float, 0, 1, low_open=True)`` takes ``(0, 1]``; ``str()`` of it is that range, so a
    help text can say ``in %(type)s``.
    """

    def __call__(self, text: str) -> int | float:
        return KindArg(self)(text)

    def check_part(self, flag: str, text: str) -> int | float:
        """``text`` (one part of a composite option) as a number in range, else a :class:`UsageError`."""
        try:
            return self.parse(text)
        except InvalidArgumentError:
            raise UsageError(f"{flag}: expected {self.describe()}, not {text!r}") from None

    def __repr__(self) -> str:
        return f"Number({self.kind.__name__}, {self})"


class Numbers(checks.Numbers):
    """An argparse type: ``count`` comma-separated numbers of one :class:`Number` (``R,G,B``, ``X,Y,W,H``)."""

    def __call__(self, text: str) -> tuple:
        return KindArg(self)(text)


class KindArg:
    """An argparse type from a kind of :mod:`dynatex.checks`: parses with the kind, and a bad value
    is a usage error carrying the kind's message; ``str()`` is the rule, for ``%(type)s`` in help.

    >>> from dynatex.checks import Range
    >>> KindArg(Range(int, 1, 8))("3"), str(KindArg(Range(int, 1, 8)))
    (3, '1..8')
    """

    def __init__(self, rule: Kind) -> None:
        self.rule = rule

    def __call__(self, text: str):
        try:
            return self.rule.parse(text)
        except InvalidArgumentError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    def __str__(self) -> str:
        return str(self.rule)

    def __repr__(self) -> str:
        return f"KindArg({self.rule!r})"


def add_param(group: Any, param: Param, *, dest: str | None = None, default: Any = argparse.SUPPRESS) -> None:
    """Add a declared parameter to an argparse parser or group as its flag (nothing when it has none).

    The parameter's kind parses the text (:class:`KindArg`) and its :meth:`~dynatex.params.Param.help`
    is the help. A :class:`~dynatex.checks.Flag` is a switch (``--no-NAME`` when it defaults to
    True); a kind with ``repeat`` may be given several times (None when never given). ``default`` is argparse's SUPPRESS
    unless given: a flag the user did not give then leaves the attribute unset.
    """
    flag = param.flag_name
    if flag is None:
        return
    dest = dest or param.name
    help_text = param.help().replace("%", "%%")
    if isinstance(param.kind, Flag):
        name, action = ("--no-" + flag[2:], "store_false") if param.default else (flag, "store_true")
        if param.default:  # the switch turns off what the declaration describes
            help_text = f"turn off what is on by default: {param.doc}".replace("%", "%%")
        group.add_argument(name, dest=dest, action=action, default=default, help=help_text)
        return
    metavar = (
        param.extra.get("metavar")
        or param.kind.metavar
        or (str(param.kind) if isinstance(param.kind, Choice) else flag.lstrip("-").upper().replace("-", "_"))
    )
    action = "append" if param.kind.repeat else "store"
    if action == "append" and default is not argparse.SUPPRESS:
        default = None  # argparse would append to the declared default itself
    group.add_argument(
        flag, dest=dest, type=KindArg(param.kind), action=action, metavar=metavar, default=default, help=help_text
    )


#: Shared declarations.
positive_int = Number(int, 1, MAX_COUNT)
count = Number(int, 0, MAX_COUNT)
seed = Number(int, 0, MAX_SEED)


#: ``WxH`` -> ``(h, w)``, each side in 1..MAX_SIDE: the command line writes width first, Python
#: passes sizes height first like a frame's shape (``--grid COLSxROWS`` -> ``(rows, cols)``).
size_arg = KindArg(Size(MAX_SIDE))


def load_clip_arg(path: str, **options):
    """:func:`~dynatex.analyzer.video.load_clip_path` of a command-line clip (imported when used:
    the parser is built without the analyzer)."""
    from ..analyzer.video import load_clip_path

    return load_clip_path(path, **options)


def tqdm_progress(desc: str, enabled: bool = True) -> Callable[[int, int | None], None] | None:
    """A ``progress(done, total)`` callback drawing a tqdm bar on stderr (None when disabled)."""
    if not enabled:
        return None
    from tqdm import tqdm

    bar = None

    def update(done: int, total: int | None) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, desc=desc, unit="it", file=sys.stderr, leave=False, disable=not sys.stderr.isatty())
        if total is not None and bar.total != total:
            bar.total = total
        bar.n = done
        bar.refresh()
        if total is not None and done >= total:
            bar.close()

    return update


__all__ = [
    "MAX_COUNT",
    "MAX_SEED",
    "MAX_SIDE",
    "KindArg",
    "add_param",
    "Number",
    "Numbers",
    "UsageError",
    "count",
    "load_clip_arg",
    "positive_int",
    "seed",
    "size_arg",
    "tqdm_progress",
]
