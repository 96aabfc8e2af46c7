"""What every player mode shares: opening a texture, the frame contract, state, backends."""

from __future__ import annotations

import difflib
import functools
import inspect
import os
import threading
from collections.abc import Callable, Iterator
from typing import Any, ClassVar

import numpy as np

from ..checks import MAX_SEED, Choice, Range, Text, check_int, check_out, check_seed
from ..errors import ArgumentTypeError, InvalidArgumentError
from ..params import Param
from ..tiledb import Texture, TileDB
from .controls import Capabilities, Control, controls_of, document
from .engines import BACKENDS
from .errors import PlayerClosedError, PlayerForkedError, UnknownControlError
from .pixels import FORMATS, pixel_format

#: what a player's ``backend`` may be: a backend, or "auto" (OpenCL on a verified device, else numpy)
BACKEND_CHOICES = ("auto", *BACKENDS)

#: the parameters every mode takes, in the order of its docstring
COMMON_OPTIONS: tuple[Param, ...] = (
    Param(
        "db", Text("path or TileDB"), None, "The tile database (a path or an open TileDB).", flag=None, default_doc=""
    ),
    Param("texture", Text("NAME"), None, "Texture name.", optional=True, default_doc="the database's only texture"),
    Param(
        "backend",
        Choice(*BACKEND_CHOICES),
        "auto",
        "auto: OpenCL on the first device that passed the self-test (the numpy reference for an engine "
        "the self-test measured slower there than numpy), else the numpy reference with one "
        "warning; opencl: a verified device or OpenCLUnavailableError; numpy: the reference.",
    ),
    Param(
        "device",
        Text("P:D|NAME"),
        None,
        "OpenCL device: index P:D or a name substring (see dynatex.player.opencl.context.get_context).",
        optional=True,
        default_doc="the first verified device",
    ),
    Param(
        "format",
        Choice(*FORMATS),
        "RGB",
        "Pixel format of the frames, written by the kernels (alpha 255); the commands' output files decide their own.",
        flag=None,
    ),
    Param(
        "seed", Range(int, 0, MAX_SEED), 0, "Seed of the mode's random choices; the same seed gives the same frames."
    ),
)

_fallback_warned = False
#: OpenCL objects of players inherited by a forked child: kept, never released there (the driver
#: belongs to the parent; releasing them in the child can hang).
_inherited: list[Any] = []


def _checked_init(init: Callable[..., None]) -> Callable[..., None]:
    """``init`` of a mode class, wrapped: the outermost constructor call checks its keywords against
    the mode's declarations (the library's argument error, naming the options, rather than Python's
    TypeError) and, once it returns, seals the player (see :meth:`Player.__setattr__`)."""

    @functools.wraps(init)
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        outer = "_sealed" not in self.__dict__
        if outer:
            object.__setattr__(self, "_sealed", False)
            check_options(type(self), kwargs)
        init(self, *args, **kwargs)
        if outer:
            object.__setattr__(self, "_sealed", True)

    __init__._checked = True  # type: ignore[attr-defined]
    return __init__


def _constructor(cls: type) -> Callable[..., None]:
    """The constructor of mode class ``cls``, made from its declarations: ``(db, texture=None, *,
    backend, device, format, seed, <its options>, <its controls' starting values>)`` with the
    declared defaults (the controls' from :meth:`Player._open`'s signature), all opened by
    :meth:`Player.__init__`."""

    def __init__(self, db: str | os.PathLike | TileDB, texture: str | None = None, **options: Any) -> None:
        Player.__init__(self, db, texture, **options)

    keywords = [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default)
        for name, default in _defaults(cls).items()
    ]
    __init__.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        [
            inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD),
            inspect.Parameter("db", inspect.Parameter.POSITIONAL_OR_KEYWORD),
            inspect.Parameter("texture", inspect.Parameter.POSITIONAL_OR_KEYWORD, default=None),
            *keywords,
        ]
    )
    __init__.__qualname__ = f"{cls.__qualname__}.__init__"
    return _checked_init(__init__)


def _defaults(cls: type) -> dict[str, Any]:
    """Every keyword mode class ``cls`` takes and its default: the declared options (common, then
    the mode's), then the controls' starting values its :meth:`Player._open` names."""
    out = {p.name: p.default for p in (*COMMON_OPTIONS, *cls.options) if p.name not in ("db", "texture")}
    for p in inspect.signature(cls._open).parameters.values():
        if p.kind is p.KEYWORD_ONLY and p.name not in out:
            out[p.name] = p.default
    return out


def _rule(cls: type, name: str) -> Param:
    """The declared rule of option or control ``name`` of mode class ``cls``."""
    for p in (*COMMON_OPTIONS, *cls.options):
        if p.name == name:
            return p
    return cls.controls()[name].param


@functools.cache
def _keywords(cls: type) -> list[str]:
    """The keywords mode class ``cls`` takes: the declared options, then any other keyword its
    constructor names (a control's starting value, for example)."""
    known = [p.name for p in (*COMMON_OPTIONS, *cls.options)]
    for p in inspect.signature(cls.__init__).parameters.values():
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name != "self" and p.name not in known:
            known.append(p.name)
    return known


def check_options(cls: type, options: dict[str, Any]) -> None:
    """Refuse a keyword that mode class ``cls`` does not take, naming the ones it takes."""
    known = _keywords(cls)
    unknown = [name for name in options if name not in known]
    if not unknown:
        return
    name = unknown[0]
    hint = ""
    if name == "size" and not cls.capabilities.any_size:
        from .modes import MODES, player_class

        any_size = [m for m in MODES if player_class(m).capabilities.any_size]
        hint = f" (it plays at the size its model fixes; modes of any size: {', '.join(any_size)})"
    elif name in cls.controls():
        hint = f" ({name} is a control: set player.{name} after opening)"
    else:
        close = difflib.get_close_matches(name, [*known, *cls.controls()], 1)
        if close and close[0] in cls.controls():
            hint = f" (did you mean the control {close[0]!r}? set player.{close[0]} after opening)"
        elif close:
            hint = f" (did you mean {close[0]!r}?)"
    raise ArgumentTypeError(f"mode {cls.mode!r} takes no option {name!r}{hint}; its options: {', '.join(known[1:])}")


class _either:
    """A method bound to the instance when called on one, else to the class."""

    def __init__(self, func: Callable[..., Any]) -> None:
        self.func = func
        functools.update_wrapper(self, func)

    def __get__(self, obj: Any, owner: type) -> Callable[[], Any]:
        return functools.partial(self.func, owner if obj is None else obj)


class Player:
    """Base class of the player modes.

    A player opens one texture of a database, builds and warms its kernels in the
    constructor and then produces ``(H, W, 3)`` uint8 frames with :meth:`next_frame`.
    Controls are plain attributes checked on assignment; a change takes effect on the
    next frame. :meth:`get_state` / :meth:`set_state` save and restore everything that
    decides future frames (position, controls, random generator).

    ``backend`` is "auto" (default: OpenCL on the first device that passed the self-test,
    else the numpy reference with one warning), "opencl" (a verified device or
    :class:`~dynatex.player.OpenCLUnavailableError`) or "numpy" (the reference);
    ``device`` names an OpenCL device (see :func:`dynatex.player.opencl.context.get_context`).
    ``format`` is the frames' pixel format: "RGB" (default), "RGBA" or "BGRA" (alpha 255),
    written straight from the kernels (:mod:`dynatex.player.pixels`); :attr:`shape` ends in
    its bytes per pixel.

    Subclasses set ``mode`` and the ``method`` they play, declare their live controls as
    :class:`~.controls.Control` attributes, their constructor options in ``options`` and what
    they can do in ``capabilities`` (:mod:`dynatex.player.controls`; the constructor, the CLI
    and the docstring follow from these), implement ``_open(**options)`` (model and engine),
    ``_start(out)``, ``_native_loop`` when they have a loop of their own, and
    ``_get_state``/``_set_state`` for the state that is not a control (position, random
    generator). :meth:`set_state` is all or nothing:
    every control entry is checked first, and when anything raises the state taken before
    is applied again; a missing entry's KeyError becomes the ValueError "state lacks '...'".

    Threads: a player may be shared between threads. :meth:`next_frame`, :meth:`start_frame`,
    :meth:`get_state`, :meth:`set_state` and :meth:`close` take the player's lock, so concurrent
    calls run one after the other and each frame is produced once (which thread gets which frame
    is the order they take the lock); a control assigned from another thread takes effect on a
    frame not yet begun. Processes: an OpenCL player cannot cross ``os.fork()``; in the child it
    raises :class:`PlayerForkedError` (open a new player there); a numpy player goes on. After
    :meth:`close` every call raises :class:`PlayerClosedError`.
    """

    mode: ClassVar[str] = ""
    #: the analysis method whose model the mode plays (``dynatex analyze --methods``; the database
    #: layer knows the same pairs as ``tiledb.database.MODE_METHOD``, and a test holds them equal)
    method: ClassVar[str] = ""
    _controls: ClassVar[dict[str, Control]] = {}
    #: constructor options beyond :data:`COMMON_OPTIONS` (fixed for the player's lifetime)
    options: ClassVar[tuple[Param, ...]] = ()
    #: options (or controls' starting values) checked before the database opens
    checked_first: ClassVar[tuple[str, ...]] = ()
    capabilities: ClassVar[Capabilities] = Capabilities()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls._controls = controls_of(cls)
        init = cls.__dict__.get("__init__")
        if init is None:
            cls.__init__ = _constructor(cls)
        elif not getattr(init, "_checked", False):
            cls.__init__ = _checked_init(init)
        if cls.__dict__.get("mode"):
            document(cls, COMMON_OPTIONS)

    @_either
    def controls(self_or_cls) -> dict[str, Control]:
        """The mode's live controls by name, in declaration order: on the class every control it
        declares, on an open player those its texture offers (see ``Control.offered``)."""
        offered = self_or_cls.__dict__.get("_offered") if isinstance(self_or_cls, Player) else None
        return self_or_cls._controls if offered is None else offered

    def __setattr__(self, name: str, value: Any) -> None:
        """Once the player is open, setting an attribute it does not have (``player.sped = 2``)
        raises :class:`UnknownControlError` naming its controls, instead of doing nothing."""
        if (
            name.startswith("_")
            or not self.__dict__.get("_sealed", False)
            or name in self.__dict__
            or hasattr(type(self), name)
        ):
            object.__setattr__(self, name, value)
            return
        controls = list(self.controls())
        close = difflib.get_close_matches(name, controls, 1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise UnknownControlError(
            f"a {self.mode!r} player has no control {name!r}: {hint}its controls are {', '.join(controls) or 'none'}"
        )

    def __init__(self, db: str | os.PathLike | TileDB, texture: str | None = None, **options: Any) -> None:
        """Open ``texture`` of ``db`` with ``options`` (any left out take their declared defaults),
        then the mode's own part (:meth:`_open`); a failure anywhere closes what was opened. A mode
        writes no constructor: its signature is made from its declarations (:func:`_constructor`)."""
        cls = type(self)
        values = {**_defaults(cls), **options}
        for name in cls.checked_first:  # refused before the database opens
            values[name] = _rule(cls, name).check(values[name])
        backend, device, format = values.pop("backend"), values.pop("device"), values.pop("format")
        backend = Choice(*BACKEND_CHOICES).check("backend", backend)
        #: the backend and device the caller asked for (``auto`` may still take numpy for an engine)
        self._asked = (backend, device)
        self._lock = threading.RLock()
        self._closed = False
        self._pid = os.getpid()
        for control in self.controls().values():  # every control starts at its declared default
            setattr(self, control.attr, control.param.default)
        #: the frames' pixel format (:data:`dynatex.player.pixels.FORMATS`)
        self.format = pixel_format(format)
        self.queue = None
        self.ctx = None
        #: the engine that draws the frames (set by the mode; closed with the player)
        self.engine: Any = None
        self.backend = backend
        self._own_db = not isinstance(db, TileDB)
        self.db = TileDB(db) if self._own_db else db
        try:
            self.texture: Texture = self.db.texture(texture)
        except BaseException:
            self.close()
            raise
        if backend != "numpy":
            try:
                self.ctx = _context(backend, device)
            except BaseException:
                self.close()
                raise
        if self.ctx is None:
            self.backend = "numpy"
        else:
            import pyopencl as cl

            self.backend = "opencl"
            self.queue = cl.CommandQueue(self.ctx)
        self.frame_index = 0
        try:
            self._open(**values)
        except BaseException:
            self.close()
            raise
        self._offered = {n: c for n, c in type(self)._controls.items() if c.offered is None or c.offered(self)}

    def _open(self, **options: Any) -> None:
        """The mode's part of opening: read its model, open its engine, warm it. It takes the
        mode's declared options (and controls' starting values) by name, as keywords."""

    # -- frame contract --------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        """``(height, width, bytes)`` of the frames this player produces: ``bytes`` 3 for RGB, 4 for
        RGBA and BGRA (subclasses set ``_shape``)."""
        return self._shape

    def reseed(self, seed: int) -> None:
        """Restart the player's random generator from ``seed``; :meth:`_on_reseed` says what else."""
        self.seed = check_seed("seed", seed)
        self._rng = np.random.Generator(np.random.PCG64(self.seed))
        self._on_reseed()

    def _on_reseed(self) -> None:
        """Hook run after :meth:`reseed` (for example to redraw a random arrangement)."""

    @property
    def still_after(self) -> int | None:
        """Frames after which the picture stops changing (a clock that stops), None when it never does."""
        return None

    @property
    def bytes_per_frame(self) -> int | None:
        """Bytes of memory one frame must move at least (for roofline figures), if known."""
        return None

    def _usable(self) -> None:
        """Raise when the player was closed or crossed a fork with an OpenCL context."""
        if self._closed:
            raise PlayerClosedError(f"this {self.mode} player was closed (close() was called); open a new one")
        if self.ctx is not None and os.getpid() != self._pid:
            raise PlayerForkedError(
                f"this {self.mode} player's OpenCL context belongs to process {self._pid}, not to this "
                f"child made by os.fork(); open a new player in the child (or use backend='numpy')"
            )

    def next_frame(self, out: np.ndarray | None = None) -> np.ndarray:
        """Produce the next frame as ``(H, W, 3)`` uint8, into ``out`` when given."""
        with self._lock:
            self._usable()
            if out is None:
                out = np.empty(self.shape, np.uint8)
            else:
                check_out(out, self.shape)
            self._render(out)
            self.frame_index += 1
            return out

    def start_frame(self, out: np.ndarray) -> PendingFrame:
        """Start producing the next frame into ``out`` and return at once (double buffering).

        The frame is complete after ``handle.wait()``; until then ``out`` must not be read
        or reused. Alternate two buffers to overlap frame production with the caller's work.
        Every mode leaves the OpenCL frame in flight; the numpy backend renders before returning.
        """
        with self._lock:
            self._usable()
            check_out(out, self.shape)
            event = self._start(out)
            self.frame_index += 1
            return PendingFrame(out, event)

    def _start(self, out: np.ndarray):
        """Begin rendering the next frame into ``out`` and advance; return an event to wait on,
        or None when ``out`` is complete. Every mode implements this."""
        raise NotImplementedError

    def frames(self, count: int, *, loop: bool = False) -> Iterator[np.ndarray]:
        """Yield ``count`` new frames (each a fresh array).

        With ``loop`` the frames form a closed loop, the last leading into the first as any
        other step does (the mode's method: :mod:`dynatex.player.loop`; tiles and turnpoints
        yield the whole number of their loops nearest ``count``, at the source's pace); they
        are rendered before the first is yielded."""
        count = check_int("count", count, 0)
        if loop and count:
            from .loop import loop_frames

            yield from loop_frames(self, count, keep_pace=True)[0]
            return
        for _ in range(count):
            yield self.next_frame()

    def _native_loop(self, count: int | None, keep_pace: bool) -> tuple[np.ndarray, str, float]:
        """``(frames, how, pace)``: the frames of the mode's own loop, for a mode whose
        ``capabilities.native_loop`` says it has one (:func:`dynatex.player.loop.loop_frames`)."""
        raise NotImplementedError(f"mode {self.mode!r} has no loop of its own")

    def _render(self, out: np.ndarray) -> None:
        event = self._start(out)
        if event is not None:
            event.wait()

    # -- state -----------------------------------------------------------------
    def get_state(self) -> dict[str, Any]:
        """Everything that decides future frames, as plain Python and numpy values: every
        control, the mode's position and random generator."""
        with self._lock:
            self._usable()
            state = {name: c.saved(self) for name, c in self.controls().items()}
            state.update(self._get_state())
            state["mode"] = self.mode
            state["texture"] = self.texture.name
            state["frame_index"] = self.frame_index
            return state

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore a state from :meth:`get_state` of a player of the same mode and texture."""
        if not isinstance(state, dict) or state.get("mode") != self.mode:
            raise InvalidArgumentError(f"state must come from a {self.mode!r} player")
        if state.get("texture") != self.texture.name:
            raise InvalidArgumentError(f"state is for texture {state.get('texture')!r}, not {self.texture.name!r}")
        with self._lock:
            before = self.get_state()
            try:
                self._apply_state(state)
            except BaseException as exc:
                self._apply_state(before)  # all or nothing: a bad entry leaves the player as it was
                if isinstance(exc, KeyError):
                    raise InvalidArgumentError(f"state lacks {exc.args[0]!r}") from None
                raise

    def _apply_state(self, state: dict[str, Any]) -> None:
        frame_index = check_int("state frame_index", state["frame_index"], 0)
        controls = {name: c.param.check(state[name]) for name, c in self.controls().items()}
        self._set_state(state)
        for name, value in controls.items():
            setattr(self, name, value)
        self.frame_index = frame_index

    def _get_state(self) -> dict[str, Any]:
        raise NotImplementedError

    def _set_state(self, state: dict[str, Any]) -> None:
        raise NotImplementedError

    # -- lifetime ----------------------------------------------------------------
    def close(self) -> None:
        """Finish the frames in flight, release the engine's device memory and the database.
        Closing again does nothing; in a forked child the OpenCL objects are left to the parent."""
        with getattr(self, "_lock", threading.RLock()):
            self._closed = True
            if self.ctx is not None and os.getpid() != self._pid:
                _inherited.append((self.engine, self.queue, self.ctx))
                self.engine = self.queue = self.ctx = None
            if self.queue is not None:
                self.queue.finish()
            if getattr(self, "engine", None) is not None:
                self.engine.close()
                self.engine = None
            if getattr(self, "_own_db", False) and getattr(self, "db", None) is not None:
                self.db.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _prefer_faster(self, backend: str, device: str | None, engine: str) -> None:
        """Under ``backend="auto"`` with no device named, take the numpy reference for
        ``engine`` unless the self-test measured OpenCL clearly faster on this device
        (:func:`.opencl.verify.prefers_opencl` on Verdict.speed). A figure missing, unsettled, old or
        from another configuration is measured first, in a child (:func:`.opencl.context.engine_speed`:
        seconds, once, on the first player of a size the self-test did not time); an engine that
        cannot be measured stays on OpenCL."""
        if backend != "auto" or device is not None or os.environ.get("PYOPENCL_CTX") or self.ctx is None:
            return
        from .opencl.context import engine_speed

        figure = engine_speed(self.ctx.devices[0], engine)
        if figure is not None and not figure.get("opencl", False):
            self.ctx = self.queue = None
            self.backend = "numpy"


class PendingFrame:
    """A frame in flight from :meth:`Player.start_frame`."""

    def __init__(self, out: np.ndarray, event: Any = None) -> None:
        self.out = out
        self._event = event

    @property
    def event(self) -> Any:
        """The OpenCL event after which the frame is complete (None once it is known to be)."""
        return self._event

    @property
    def done(self) -> bool:
        if self._event is None:
            return True
        import pyopencl as cl

        return self._event.command_execution_status == cl.command_execution_status.COMPLETE

    def wait(self) -> np.ndarray:
        """Block until the frame is complete and return it."""
        if self._event is not None:
            self._event.wait()
            self._event = None
        return self.out


def rng_from_state(state: Any) -> np.random.Generator:
    """The PCG64 generator whose ``bit_generator.state`` a player's :meth:`Player.get_state` saved."""
    rng = np.random.Generator(np.random.PCG64())
    rng.bit_generator.state = state
    return rng


def _context(backend: str, device: str | None):
    """The OpenCL context for a player, or None when ``backend="auto"`` finds no verified device
    (the numpy backend then, with one warning per process). A device asked for by ``device``
    or ``PYOPENCL_CTX`` is never silently replaced."""
    global _fallback_warned
    from .opencl import context as opencl

    try:
        return opencl.get_context(device)
    except opencl.OpenCLUnavailableError as exc:
        if backend == "opencl" or device is not None or os.environ.get("PYOPENCL_CTX"):
            raise
        if not _fallback_warned:
            _fallback_warned = True
            import warnings

            warnings.warn(f"the player uses the numpy backend (slower): {exc}", RuntimeWarning, stacklevel=4)
        return None
