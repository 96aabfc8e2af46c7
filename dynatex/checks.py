"""Argument checks shared by every layer, and the value kinds that declare them.

One home for the rules an argument must follow. A check function takes the argument's name
and value and returns the value normalized (``check_int("n", np.int64(3), 1) == 3``) or
raises an :class:`~dynatex.errors.InvalidArgumentError` that names the argument and the rule
(an :class:`~dynatex.errors.ArgumentTypeError` for a value of the wrong type).

A *kind* (:class:`Range`, :class:`Choice`, :class:`Flag`, :class:`Numbers`, :class:`Text`,
:class:`Size`, :class:`Either`) is a rule as an object: the same object checks a Python value
(:meth:`~Range.check`), parses a command-line string (:meth:`~Range.parse`) and says the
rule in words for help and docs (:meth:`~Range.describe`, ``str()``). Declarations of method
parameters and player controls (:mod:`dynatex.params`) are built from kinds, so a range is
written once. This module imports only numpy and :mod:`dynatex.errors`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import ArgumentTypeError, InvalidArgumentError

#: Largest count (frames, steps, dimensions, indices) an argument takes: beyond it, array sizes overflow.
MAX_COUNT = 2**31 - 1
#: Largest seed (NumPy's generators take any non-negative integer; a seed is stored as int64).
MAX_SEED = 2**63 - 1
#: Largest side of a size in pixels (an output, a resized clip, a quilt's canvas, a tile).
MAX_SIDE = 16384


# -- check functions ---------------------------------------------------------------------------
def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None, *, rule: str | None = None) -> int:
    """``value`` as an int in ``[lo, hi]`` (either bound may be None).

    Bools and floats are refused with an :class:`ArgumentTypeError`; a value out of range
    raises ``"{name} must be {rule}, not {value}"``. ``rule`` defaults to words for the
    bounds; pass it where a bound has a name (``"an integer in 1..n=5"``).

    Examples
    --------
    >>> check_int("n", np.int64(3), 1)
    3
    >>> check_int("n", 0, 1)
    Traceback (most recent call last):
    ...
    dynatex.errors.InvalidArgumentError: n must be an integer >= 1, not 0
    """
    v = _number(int, name, value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise InvalidArgumentError(f"{name} must be {rule or Range(int, lo, hi).describe()}, not {v}")
    return v


def check_float(name: str, value: Any, lo: float | None = None, hi: float | None = None) -> float:
    """``value`` as a finite float in ``[lo, hi]`` (either bound may be None).

    Examples
    --------
    >>> check_float("speed", 2, -3, 3)
    2.0
    >>> check_float("speed", float("nan"))
    Traceback (most recent call last):
    ...
    dynatex.errors.InvalidArgumentError: speed must be a finite number, not nan
    """
    v = _number(float, name, value)
    if not (math.isfinite(v) and (lo is None or v >= lo) and (hi is None or v <= hi)):
        raise InvalidArgumentError(f"{name} must be {Range(float, lo, hi).describe()}, not {value!r}")
    return v


def _number(kind: type, name: str, value: Any) -> Any:
    """``value`` as an ``int`` (integers only, bools refused) or a ``float`` (any real number)."""
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ArgumentTypeError(f"{name} must be an integer, not {value!r}")
        return int(value)
    if isinstance(value, (str, bytes)):
        raise ArgumentTypeError(f"{name} must be a number, not {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{name} must be a number, not {value!r}") from None


def check_seed(name: str, value: Any) -> int:
    """``value`` as a seed: a non-negative integer."""
    return check_int(name, value, 0)


def check_choice(name: str, value: Any, choices: Sequence[Any]) -> Any:
    """``value`` if it is one of ``choices``.

    >>> check_choice("end", "loop", ("hold", "loop"))
    'loop'
    """
    return Choice(*choices).check(name, value)


def check_size(name: str, value: Any, max_side: int) -> tuple[int, int]:
    """``value`` as a ``(height, width)`` pair of integers in ``1..max_side``.

    >>> check_size("size", (24, 40), 16384)
    (24, 40)
    """
    return Size(max_side).check(name, value)


def check_out(out: Any, shape: tuple[int, ...]) -> None:
    """Check that ``out`` is a C-contiguous, writeable uint8 array of ``shape`` (a frame buffer)."""
    if not isinstance(out, np.ndarray):
        raise ArgumentTypeError(f"out must be a numpy array, not {type(out).__name__}")
    if out.dtype != np.uint8 or out.shape != tuple(shape):
        raise InvalidArgumentError(f"out must be uint8 with shape {tuple(shape)}, got {out.dtype} {out.shape}")
    if not out.flags.c_contiguous or not out.flags.writeable:
        raise InvalidArgumentError("out must be C-contiguous and writeable")


def check_frames(
    frames: Any, *, name: str = "frames", min_frames: int = 1, uint8: bool = False, allow_nonfinite: bool = False
) -> np.ndarray:
    """Return ``frames`` as a ``(T, H, W, C)`` array, or raise an error naming ``name``.

    Parameters
    ----------
    frames : array_like
        ``(T, H, W)`` or ``(T, H, W, C)`` with ``C`` in (1, 3); uint8 or a real dtype (0..255 scale).
    name : str
        What to call the array in error messages.
    min_frames : int
        Fewest frames accepted.
    uint8 : bool
        Accept only uint8 frames (a clip to analyse).
    allow_nonfinite : bool
        Accept NaN/inf values (only the stability metric does).

    Examples
    --------
    >>> check_frames(np.zeros((4, 8, 6), np.uint8)).shape
    (4, 8, 6, 1)
    """
    if not isinstance(frames, np.ndarray):
        if isinstance(frames, (list, tuple)):
            frames = np.asarray(frames)
        else:
            raise ArgumentTypeError(f"{name} must be a numpy array of frames, not {type(frames).__name__}")
    if uint8 and frames.dtype != np.uint8:
        raise ArgumentTypeError(f"{name} must be uint8 frames, not {frames.dtype}")
    if frames.dtype.kind not in "uif" or frames.dtype == np.bool_:
        raise ArgumentTypeError(f"{name} must hold numbers (uint8 or float), not {frames.dtype}")
    if frames.ndim == 3:
        frames = frames[..., None]
    if frames.ndim != 4 or frames.shape[-1] not in (1, 3):
        raise InvalidArgumentError(
            f"{name} must be (T, H, W) or (T, H, W, C) with C in (1, 3), not shape {frames.shape}"
        )
    if frames.shape[0] < min_frames:
        what = "is empty (no frames)" if frames.shape[0] == 0 else f"has {frames.shape[0]} frame(s)"
        raise InvalidArgumentError(f"{name} {what}; at least {min_frames} needed")
    if frames.shape[1] < 1 or frames.shape[2] < 1:
        raise InvalidArgumentError(f"{name} has empty frames ({frames.shape[2]}x{frames.shape[1]} pixels)")
    if not allow_nonfinite and frames.dtype.kind == "f":
        bad = int((~np.isfinite(frames.reshape(len(frames), -1))).any(axis=1).sum())
        if bad:
            raise InvalidArgumentError(f"{name} holds NaN or inf in {bad} frame(s)")
    return frames


# -- kinds -------------------------------------------------------------------------------------
class Kind:
    """A rule for one argument: checks Python values, parses command-line text, says itself."""

    #: what the command line shows for the value (None: argparse's default)
    metavar: str | None = None
    #: the command-line option may be given several times (its values make a list)
    repeat: bool = False

    def check(self, name: str, value: Any) -> Any:
        """``value`` normalized, or an :class:`InvalidArgumentError` naming ``name``."""
        raise NotImplementedError

    def parse(self, text: str) -> Any:
        """The value ``text`` (from a command line) stands for, or an :class:`InvalidArgumentError`."""
        return self.check("value", text)

    def describe(self) -> str:
        """The rule in words, as it completes "must be ...": ``"an integer in 1..8"``."""
        raise NotImplementedError

    def describe_text(self) -> str:
        """The rule for the text a command line gives (where it differs from the Python value's)."""
        return self.describe()

    def __str__(self) -> str:
        return self.describe()


class Range(Kind):
    """A finite ``int`` or ``float`` within bounds; ``low_open``/``high_open`` exclude a bound.

    Examples
    --------
    >>> speed = Range(float, -3, 3)
    >>> speed.check("speed", 2), str(speed), speed.parse(" -1.5 ")
    (2.0, '[-3, 3]', -1.5)
    >>> Range(float, 0, 1, low_open=True).describe()
    'a finite number in (0, 1]'
    """

    def __init__(
        self,
        kind: type,
        low: float | None = None,
        high: float | None = None,
        *,
        low_open: bool = False,
        high_open: bool = False,
    ) -> None:
        if kind not in (int, float):
            raise TypeError("kind must be int or float")
        self.kind, self.low, self.high = kind, low, high
        self.low_open, self.high_open = low_open, high_open

    def contains(self, v: float) -> bool:
        return (
            math.isfinite(v)
            and (self.low is None or (v > self.low if self.low_open else v >= self.low))
            and (self.high is None or (v < self.high if self.high_open else v <= self.high))
        )

    def check(self, name: str, value: Any) -> int | float:
        v = _number(self.kind, name, value)
        if not self.contains(v):
            raise InvalidArgumentError(f"{name} must be {self.describe()}, not {v if self.kind is int else value!r}")
        return v

    def parse(self, text: str) -> int | float:
        try:
            value = self.kind(text.strip())
        except (TypeError, ValueError, OverflowError):
            raise InvalidArgumentError(f"expected {self.describe()}, not {text!r}") from None
        if not self.contains(value):
            raise InvalidArgumentError(f"expected {self.describe()}, not {text!r}")
        return value

    def describe(self) -> str:
        what = "an integer" if self.kind is int else "a finite number"
        rng = self.bounds()
        if not rng:
            return what
        if self.kind is int and self.low == 0 and self.high is None:
            return "a non-negative integer"
        return f"{what} {rng}" if rng[0] in "<>" else f"{what} in {rng}"

    def bounds(self) -> str:
        """The bounds alone: ``"[0, 1)"``, ``"1..8"``, ``">= 0"`` (empty when unbounded)."""
        lo, hi = self.low, self.high
        if lo is None and hi is None:
            return ""
        if hi is None:
            return f"{'>' if self.low_open else '>='} {_g(lo)}"
        if lo is None:
            return f"{'<' if self.high_open else '<='} {_g(hi)}"
        if self.kind is int and not (self.low_open or self.high_open):
            return f"{_g(lo)}..{_g(hi)}"
        return f"{'(' if self.low_open else '['}{_g(lo)}, {_g(hi)}{')' if self.high_open else ']'}"

    def __str__(self) -> str:
        return self.bounds()

    def __repr__(self) -> str:
        return f"Range({self.kind.__name__}, {self.bounds()})"


def _g(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:g}"


class Choice(Kind):
    """One of a fixed set of values (strings on the command line).

    >>> Choice("hold", "loop").check("end", "pingpong")
    Traceback (most recent call last):
    ...
    dynatex.errors.InvalidArgumentError: end must be one of 'hold', 'loop', not 'pingpong'
    """

    def __init__(self, *choices: Any) -> None:
        self.choices = tuple(choices)

    def check(self, name: str, value: Any) -> Any:
        try:
            ok = value in self.choices
        except TypeError:
            ok = False
        if not ok:
            raise InvalidArgumentError(f"{name} must be {self.describe()}, not {value!r}")
        return value

    def parse(self, text: str) -> Any:
        for c in self.choices:
            if str(c) == text:
                return c
        raise InvalidArgumentError(f"expected {self.describe()}, not {text!r}")

    def describe(self) -> str:
        return "one of " + ", ".join(repr(c) for c in self.choices)

    def __str__(self) -> str:
        return "{" + ",".join(str(c) for c in self.choices) + "}"


class Flag(Kind):
    """A bool (on the command line a switch that takes no value)."""

    def check(self, name: str, value: Any) -> bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ArgumentTypeError(f"{name} must be True or False, not {value!r}")
        return bool(value)

    def describe(self) -> str:
        return "True or False"


class Numbers(Kind):
    """``count`` values of one :class:`Range`: a tuple in Python, ``a,b,c`` on the command line.

    >>> Numbers(Range(float, 0, 10), 3, "C,M,F").parse("1,2,0.5")
    (1.0, 2.0, 0.5)
    """

    def __init__(self, item: Range, count: int, form: str) -> None:
        self.item, self.count, self.form = item, count, form
        self.metavar = form

    def check(self, name: str, value: Any) -> tuple:
        if isinstance(value, (str, bytes)):
            raise ArgumentTypeError(f"{name} must be {self.describe()}, not {value!r}")
        try:
            items = list(value)
        except TypeError:
            raise ArgumentTypeError(f"{name} must be {self.describe()}, not {value!r}") from None
        if len(items) != self.count:
            raise InvalidArgumentError(f"{name} must be {self.describe()}, not {value!r}")
        return tuple(self.item.check(f"{name}[{i}]", v) for i, v in enumerate(items))

    def parse(self, text: str) -> tuple:
        parts = text.split(",")
        try:
            if len(parts) != self.count:
                raise InvalidArgumentError("count")
            return tuple(self.item.parse(p) for p in parts)
        except InvalidArgumentError:
            raise InvalidArgumentError(f"expected {self.describe()}, not {text!r}") from None

    def describe(self) -> str:
        return f"{self.form}: {self.count} numbers, each {self.item.describe()}"

    def __str__(self) -> str:
        return f"{self.form}, each {self.item.describe()}"


class Size(Kind):
    """A ``(height, width)`` pair of integers in ``min_side..max_side``; ``WxH`` on the command line.

    >>> Size(16384).parse("40x24")
    (24, 40)
    """

    metavar = "WxH"

    def __init__(self, max_side: int, min_side: int = 1) -> None:
        self.max_side, self.min_side = max_side, min_side

    def check(self, name: str, value: Any) -> tuple[int, int]:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
            raise ArgumentTypeError(f"{name} must be (height, width), not {value!r}")
        if len(value) != 2:
            raise InvalidArgumentError(
                f"{name} must be (height, width), two integers, not {len(value)} values {value!r}"
            )
        if any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in value):
            raise ArgumentTypeError(f"{name} must be (height, width) integers, not {value!r}")
        h, w = int(value[0]), int(value[1])
        if not (self.min_side <= h <= self.max_side and self.min_side <= w <= self.max_side):
            raise InvalidArgumentError(
                f"{name} must be (height, width) with each side in {self.min_side}..{self.max_side}, not {value!r}"
            )
        return h, w

    def parse(self, text: str) -> tuple[int, int]:
        parts = text.lower().split("x")
        side = Range(int, self.min_side, self.max_side)
        try:
            if len(parts) != 2:
                raise InvalidArgumentError("form")
            w, h = (side.parse(p) for p in parts)
        except InvalidArgumentError:
            raise InvalidArgumentError(f"expected WIDTHxHEIGHT, each side in {side}, not {text!r}") from None
        return h, w

    def describe(self) -> str:
        return f"(height, width), each in {self.min_side}..{self.max_side}"

    def describe_text(self) -> str:
        return f"WIDTHxHEIGHT, each side in {self.min_side}..{self.max_side}"

    def __str__(self) -> str:
        return self.describe_text()


class Array(Kind):
    """A float array of finite values within bounds (``ndim`` dimensions when given); Python only.

    >>> Array(0, 10, ndim=1).check("weights", [1, 2.5])
    array([1. , 2.5])
    """

    def __init__(self, low: float | None = None, high: float | None = None, *, ndim: int | None = None) -> None:
        self.range = Range(float, low, high)
        self.ndim = ndim

    def check(self, name: str, value: Any) -> np.ndarray:
        try:
            arr = np.array(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ArgumentTypeError(f"{name} must be {self.describe()}, not {type(value).__name__}") from None
        if self.ndim is not None and arr.ndim != self.ndim:
            raise InvalidArgumentError(f"{name} must be {self.describe()}, not of shape {arr.shape}")
        if arr.size and not (
            np.isfinite(arr).all() and self.range.contains(float(arr.min())) and self.range.contains(float(arr.max()))
        ):
            raise InvalidArgumentError(f"{name} must be {self.describe()}")
        return arr

    def parse(self, text: str) -> np.ndarray:
        raise InvalidArgumentError("an array is not given on the command line")

    def describe(self) -> str:
        dims = "an array" if self.ndim is None else f"a {self.ndim}-D array"
        rng = self.range.bounds()
        return f"{dims} of finite numbers" + (f" in {rng}" if rng and rng[0] not in "<>" else f" {rng}" if rng else "")


class NpyFile(Kind):
    """An array in Python; on the command line the path of an ``.npy`` file holding it (no pickles)."""

    metavar = "FILE.npy"

    def check(self, name: str, value: Any) -> np.ndarray:
        if not isinstance(value, np.ndarray):
            raise ArgumentTypeError(f"{name} must be a numpy array, not {type(value).__name__}")
        return value

    def parse(self, text: str) -> np.ndarray:
        if not text.endswith(".npy"):
            raise InvalidArgumentError(f"expected a FILE.npy, not {text!r}")
        try:
            return np.load(text, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InvalidArgumentError(f"cannot read {text!r}: {exc}") from None

    def describe(self) -> str:
        return "a numpy array"

    def describe_text(self) -> str:
        return "a FILE.npy"


class Text(Kind):
    """A non-empty string (a path, a name, a preset); ``metavar`` names it in help."""

    def __init__(self, metavar: str | None = None) -> None:
        self.metavar = metavar

    def check(self, name: str, value: Any) -> str:
        if not isinstance(value, str) or not value:
            raise ArgumentTypeError(f"{name} must be a non-empty string, not {value!r}")
        return value

    def parse(self, text: str) -> str:
        return self.check("value", text)

    def describe(self) -> str:
        return "a non-empty string" if self.metavar is None else self.metavar


class Either(Kind):
    """The first of several kinds that takes the value (an integer or ``"auto"``).

    >>> n = Either(Range(int, 1, 100), Choice("auto"))
    >>> n.parse("auto"), n.parse("7"), n.describe()
    ('auto', 7, "an integer in 1..100 or one of 'auto'")
    """

    def __init__(self, *kinds: Kind, metavar: str | None = None) -> None:
        self.kinds = kinds
        self.metavar = metavar

    def check(self, name: str, value: Any) -> Any:
        for kind in self.kinds:
            try:
                return kind.check(name, value)
            except InvalidArgumentError:
                continue
        raise InvalidArgumentError(f"{name} must be {self.describe()}, not {value!r}")

    def parse(self, text: str) -> Any:
        for kind in self.kinds:
            try:
                return kind.parse(text)
            except InvalidArgumentError:
                continue
        raise InvalidArgumentError(f"expected {self.describe()}, not {text!r}")

    def describe(self) -> str:
        return " or ".join(k.describe() for k in self.kinds)

    def describe_text(self) -> str:
        return " or ".join(k.describe_text() for k in self.kinds)


__all__ = [
    "MAX_COUNT",
    "MAX_SEED",
    "MAX_SIDE",
    "Array",
    "Choice",
    "Either",
    "Flag",
    "Kind",
    "NpyFile",
    "Numbers",
    "Range",
    "Size",
    "Text",
    "check_choice",
    "check_float",
    "check_frames",
    "check_int",
    "check_out",
    "check_seed",
    "check_size",
]
