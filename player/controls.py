"""What a player mode declares about itself: its controls, its options and its capabilities.

A mode class declares each live control once, as a :class:`Control` attribute (name, rule,
default, doc); the declaration checks assignments, saves and restores the control with
:meth:`~dynatex.player.base.Player.get_state` / ``set_state``, gives ``dynatex play`` its
flag and writes the "Controls" section of the class docstring. Constructor options (fixed
for the player's lifetime) are declared as :class:`~dynatex.params.Param`\\ s in the class's
``options``, and what the mode can do in its :class:`Capabilities`.

Examples
--------
>>> from dynatex.checks import Range
>>> class Toy:
...     gain = Control(Range(float, 0, 2), 1.0, "Brightness gain.")
>>> t = Toy()
>>> t.gain = 1.5
>>> t.gain
1.5
>>> t.gain = 3
Traceback (most recent call last):
...
dynatex.errors.InvalidArgumentError: gain must be a finite number in [0, 2], not 3
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import Kind
from ..errors import InvalidArgumentError
from ..params import Param


@dataclass(frozen=True)
class Capabilities:
    """What a mode can do, for the tools that drive every mode alike (CLI, export, evaluate)."""

    #: plays at any output size (``size=`` option); otherwise at the size its model fixes
    any_size: bool = False
    #: reads the clip's stored frames (the texture must hold them)
    needs_frames: bool = False
    #: its frames repeat after a loop of its own (tiles, turn points): a seamless flipbook needs no blend
    native_loop: bool = False
    #: fills a masked region of the caller's frames (``inpaint``)
    inpaint: bool = False
    #: ``start_frame`` leaves the OpenCL frame in flight (double buffering)
    asynchronous: bool = True


class Control:
    """A live control of a player mode: a checked attribute that is part of the player's state.

    ``speed = Control(Range(float, -3, 3), 1.0, "doc")`` in a mode class: assigning checks
    the value against the rule (a bad value raises and keeps the old one) and stores it in
    ``self._speed``. A mode whose control has side effects (rebuilding a table) or rules that
    depend on the loaded model decorates a setter, as with ``property``: it receives the
    checked value and stores it itself::

        @speed.setter
        def speed(self, value): ...

    ``flag`` is the ``dynatex play`` option (``""``: ``--speed``; None: not on the command
    line). A player starts every control at its declared default (a mode whose default is
    computed from the model, ``None`` here, sets it in its setup); ``get_state`` saves every control.

    ``offered(player) -> bool``, when given, says whether the opened texture offers the control
    (a control that has no effect on some models); ``unoffered`` says why not. A player whose texture
    does not offer it leaves it out of ``player.controls()`` and its state, and refuses to set it.
    """

    def __init__(
        self,
        kind: Kind,
        default: Any,
        doc: str,
        *,
        flag: str | None = "",
        optional: bool = False,
        default_doc: str | None = None,
        offered: Callable[[Any], bool] | None = None,
        unoffered: str = "",
    ) -> None:
        self._spec = dict(kind=kind, default=default, doc=doc, flag=flag, optional=optional, default_doc=default_doc)
        self.offered = offered
        self.unoffered = unoffered
        self.param: Param = Param("", **self._spec)
        self.name = ""
        self.attr = ""
        self._fset: Callable[[Any, Any], None] | None = None
        self._fget: Callable[[Any], Any] | None = None

    def __set_name__(self, owner: type, name: str) -> None:
        self.name, self.attr = name, "_" + name
        self.param = Param(name, **self._spec)

    def setter(self, fset: Callable[[Any, Any], None]) -> Control:
        """Decorate the function that applies a checked value (it stores the value itself)."""
        self._fset = fset
        return self

    def getter(self, fget: Callable[[Any], Any]) -> Control:
        """Decorate the function that reads the value (for example a copy of an array)."""
        self._fget = fget
        return self

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        if self._fget is not None:
            return self._fget(obj)
        return getattr(obj, self.attr)

    def __set__(self, obj: Any, value: Any) -> None:
        offered = getattr(obj, "__dict__", {}).get("_offered")
        if offered is not None and self.name not in offered:
            raise InvalidArgumentError(f"this texture does not offer the control {self.name}: {self.unoffered}")
        value = self.param.check(value)
        if self._fset is None:
            setattr(obj, self.attr, value)
        else:
            self._fset(obj, value)

    def saved(self, obj: Any) -> Any:
        """The control's value as a state entry (arrays copied)."""
        value = self.__get__(obj)
        return value.copy() if isinstance(value, np.ndarray) else value

    def __repr__(self) -> str:
        return f"Control({self.name!r}, {self.param.kind.describe()})"


def controls_of(cls: type) -> dict[str, Control]:
    """The controls a class declares, its bases' first, in declaration order."""
    found: dict[str, Control] = {}
    for klass in reversed(cls.__mro__):
        for name, value in vars(klass).items():
            if isinstance(value, Control):
                found.pop(name, None)
                found[name] = value
            elif name in found:
                del found[name]  # a subclass replaced the control with something else
    return found


def document(cls: type, common: tuple[Param, ...]) -> None:
    """Write the "Parameters" and "Controls" sections of a mode's docstring from its declarations.

    They go before an "Examples" section if the docstring has one, else at its end.
    """
    doc = cls.__doc__ or ""
    params = (*common, *getattr(cls, "options", ()))
    sections = ["Parameters\n----------\n" + "\n".join(p.numpydoc() for p in params)]
    controls = controls_of(cls)
    if controls:
        sections.append(
            "Controls (attributes, changeable between any two frames)\n"
            "---------------------------------------------------------\n"
            + "\n".join(c.param.numpydoc() for c in controls.values())
        )
    text = "\n\n".join(sections)
    indent = "    "
    text = "\n".join(indent + line if line else line for line in text.splitlines())
    marker = f"\n{indent}Examples\n"
    if marker in doc:
        head, tail = doc.split(marker, 1)
        cls.__doc__ = f"{head.rstrip()}\n\n{text}\n{marker}{tail}"
    else:
        cls.__doc__ = f"{doc.rstrip()}\n\n{text}\n"


def markdown(classes: list[type], common: tuple[Param, ...]) -> str:
    """``player/MODES.md``: every mode's options, controls and capabilities as tables, from the declarations."""
    lines = [
        "# Player modes",
        "",
        "Generated from the modes' declarations (`python tools/write_modes_doc.py`);",
        "a test keeps it equal to them. Every mode takes the common parameters; the",
        "command line offers a mode's options and controls as flags (`dynatex play --mode MODE --help`).",
        "",
    ]

    def table(params: list[Param]) -> list[str]:
        rows = ["| name | flag | rule | default | what |", "|---|---|---|---|---|"]
        for p in params:
            flag = f"`{p.flag_name}`" if p.flag_name else "-"
            cells = [f"`{p.name}`", flag, p.kind.describe(), p.default_text() or "-", p.doc]
            rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        return rows

    lines += ["## Common parameters", "", *table(list(common)), ""]
    for cls in classes:
        caps = [f.name for f in cls.capabilities.__dataclass_fields__.values() if getattr(cls.capabilities, f.name)]
        lines += [
            f"## `{cls.mode}` ({cls.__name__})",
            "",
            (cls.__doc__ or "").strip().splitlines()[0],
            "",
            f"Capabilities: {', '.join(caps) or 'none'}.",
            "",
        ]
        if cls.options:
            lines += ["Options (fixed for the player's lifetime):", "", *table(list(cls.options)), ""]
        lines += [
            "Controls (attributes, changeable between any two frames; saved by `get_state`):",
            "",
            *table([c.param for c in controls_of(cls).values()]),
            "",
        ]
    return "\n".join(lines)


__all__ = ["Capabilities", "Control", "controls_of", "document", "markdown"]
