"""Declared parameters: the one place a method parameter or a player option or control is described.

A :class:`Param` says a parameter's name, its rule (a kind from :mod:`dynatex.checks`), its
default and what it does. Analysis methods (:mod:`dynatex.analyzer.methods`) and player modes
(:mod:`dynatex.player.controls`) declare theirs; the command line, the saved state and the
docs are generated from those declarations, so adding a parameter touches one place.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from typing import Any

from .checks import Flag, Kind


@dataclass(frozen=True)
class Param:
    """One declared parameter.

    Parameters
    ----------
    name : str
        The Python name (keyword argument, attribute, state entry).
    kind : Kind
        The rule its values follow (:class:`~dynatex.checks.Range`, :class:`~dynatex.checks.Choice`, ...).
    default : object
        The value when none is given; None with ``optional`` means "computed" (``default_doc`` says how).
    doc : str
        What it does, one sentence.
    flag : str or None
        Its command-line option; ``""`` derives ``--name-with-dashes``, None keeps it off the command line.
    optional : bool
        None is a valid value (the default is computed from the data).
    default_doc : str, optional
        The default in words, for defaults computed from the data.

    Examples
    --------
    >>> from dynatex.checks import Range
    >>> p = Param("sigma", Range(float, 0, 4096), None, "Smoothing of the offsets, pixels.", optional=True,
    ...           default_doc="half a tile")
    >>> p.flag_name, p.check(None), p.check(3)
    ('--sigma', None, 3.0)
    >>> p.help()
    'Smoothing of the offsets, pixels. A finite number in [0, 4096] (default half a tile).'
    """

    name: str
    kind: Kind
    default: Any
    doc: str
    flag: str | None = ""
    optional: bool = False
    default_doc: str | None = None
    #: free-form extras a consumer may read (for example the CLI's ``metavar``)
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @property
    def flag_name(self) -> str | None:
        """The command-line option, or None when the parameter is not on the command line."""
        if self.flag is None:
            return None
        return self.flag or "--" + self.name.replace("_", "-")

    def check(self, value: Any) -> Any:
        """``value`` normalized by the kind (None passes when ``optional``)."""
        if value is None and self.optional:
            return None
        return self.kind.check(self.name, value)

    def default_text(self) -> str:
        if self.default_doc is not None:
            return self.default_doc
        if isinstance(self.default, tuple):
            return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in self.default)
        if isinstance(self.default, float):
            return f"{self.default:g}"
        return str(self.default)

    def help(self) -> str:
        """One paragraph for ``--help``: what, the rule for the flag's text, the default."""
        if isinstance(self.kind, Flag):
            return f"{self.doc} (default {self.default_text()})"
        rule = self.kind.describe_text()
        return f"{self.doc} {rule[0].upper()}{rule[1:]} (default {self.default_text()})."

    def numpydoc(self) -> str:
        """The parameter as a numpydoc entry (``name : rule`` and the indented description)."""
        default = self.default_text()
        text = self.doc + (f" Default {default}." if default else "")
        return f"{self.name} : {self.kind.describe()}\n" + textwrap.fill(
            text, 88, initial_indent="    ", subsequent_indent="    "
        )


__all__ = ["Param"]
