"""What the projection modes (``lds``, ``mixture``) share: a player whose frame is the
projection of a small vector, advanced on the host once per frame, through a stored basis.

A model with a ``detail`` part (:mod:`dynatex.tiledb.detail`) has the projection engine add
the fine detail the projection lacks to each frame in the same pass (:mod:`~dynatex.player.engines.detail` schedules
it) and hold every pixel to the source's colour range; one with a ``gamut`` part
(:mod:`dynatex.tiledb.gamut`) has it move every colour the source never had to the nearest
one it had, last (the ``colours`` option: the sets of the frame's regions, the clip's, or none).

Look-ahead (option ``lookahead=k``): the player runs its state up to k frames ahead and
projects them in one pass over the basis (:mod:`~dynatex.player.engines.projection`), then hands them out one by
one. A control change, :meth:`set_state`, :meth:`reseed` or :meth:`advance` discards the
frames computed ahead and puts the player back at the last frame handed out (discard and
recompute), so a change applies to the very next frame, as without look-ahead, and
:meth:`get_state` is the state after the last frame handed out; after a discard the next
pass renders one frame, and each later pass twice as many, up to k (a control changed on
every frame costs what it costs without look-ahead). What look-ahead adds is time, not
latency in frames: on numpy the frame that starts a pass waits for all of its k frames; on
OpenCL the next pass renders into a second buffer while the current one is handed out, and a
frame waits only where that pass is not done yet.

A mode subclasses :class:`ProjectionPlayer` and supplies its model (``_setup``), the
vector it advances (``_vector``, ``_dim``, ``_step``) and how that vector becomes
projection coefficients (``_coefficients``). The base opens the projection engine
(:mod:`dynatex.player.engines.projection`), warms it, and provides ``precision``, the
``intensity`` control, ``bytes_per_frame``, ``advance`` and the frame paths.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ...checks import Choice, Range, check_int
from ...errors import InvalidArgumentError
from ...params import Param
from ..base import Player
from ..controls import Control
from ..engines import open_engine
from ..engines.projection import basis_shape, speed_case

PRECISIONS = ("float32", "float16")
#: what the ``colours`` option holds a frame's colours to (the model's gamut part)
COLOURS = ("local", "clip", "off")
MAX_INTENSITY = 100.0
MAX_DETAIL = 4.0
MAX_LOOKAHEAD = 64
#: frames per pass for the commands that render a known number of frames (play, export, evaluate, bench)
KNOWN_COUNT_LOOKAHEAD = 8


class ProjectionPlayer(Player):
    """Base of the modes whose frames are ``Projector`` projections of a host-side vector.

    Subclasses set ``mode`` and ``basis_name`` (the model's basis attribute) and implement
    ``_setup(model)`` (everything but the projector; it must set ``_shape`` and ``_dim``),
    ``_vector()`` (the vector of the next frame), ``_dim`` (its length), ``_step()``
    (advance it once) and ``_coefficients(v, coef)`` (write the coefficients for ``v``).
    """

    basis_name = "basis"
    options = (
        Param(
            "precision",
            Choice(*PRECISIONS),
            "float32",
            "Storage of the basis on the device; float16 halves the bytes each frame reads (faster, "
            "memory-bound) at PSNR above 45 dB against float32.",
        ),
        Param(
            "lookahead",
            Range(int, 1, MAX_LOOKAHEAD),
            None,
            "Frames rendered ahead, k per pass over the basis (memory traffic per frame about k times "
            "less). A control change, set_state, reseed or advance discards the frames not handed out "
            "and applies from the very next frame (no frames of latency); the frame that starts a pass "
            "waits for its k frames, and after a discard passes restart at 1 frame and double up to k.",
            optional=True,
            default_doc=f"1 (one frame at a time); {KNOWN_COUNT_LOOKAHEAD} in the commands that render a known "
            "number of frames",
            extra={"known_count": KNOWN_COUNT_LOOKAHEAD},
        ),
        Param(
            "colours",
            Choice(*COLOURS),
            "local",
            "Colours the clip never had, moved into its colour set (a texture analysed with a gamut "
            "part): 'local' the sets of the frame's regions, blended between their centres (a colour "
            "that is the clip's elsewhere but never here moves too; where the texture has no local "
            "sets, the clip's); 'clip' the whole clip's set, cheaper (the local sets' blend takes about "
            "a fifth of a frame's time on a CPU); 'off' none (the projection as it is: a linear model "
            "can show tints the clip never had).",
        ),
    )

    checked_first = ("precision", "lookahead", "colours")

    def _open(self, *, seed: int, precision: str, lookahead: int | None, colours: str) -> None:
        lookahead = lookahead or 1
        model = self.texture.read(self.method)
        self.model_info = dict(model.info)
        self.precision = precision
        #: what frames' colours are held to (the ``colours`` option)
        self.colours = colours
        if model.gamut is not None and colours != "local":
            model.gamut = None if colours == "off" else dataclasses.replace(model.gamut, local=None)
        self._setup(model)
        basis = self._basis(model)
        rows, values = basis_shape(basis)
        case = speed_case(precision, values, lookahead, model.detail is not None, rows)
        self._prefer_faster(*self._asked, case)
        if precision == "float16":
            basis = tuple(b.astype(np.float16) for b in basis)
        self.engine = open_engine(
            "projection",
            basis,
            model.mean,
            shape=self._shape,
            channels=self.texture.source.channels,
            ctx=self.ctx,
            queue=self.queue,
            format=self.format,
            frames=lookahead,
            detail=model.detail,
            gamut=model.gamut,
            tone=model.tone,
        )
        self.basis_bytes = self.engine.basis_bytes
        #: the detail's arrays and schedule (None: the model has none, or set so to project alone)
        self.detail_engine = self.engine.detail
        self._detail_clock = 0.0
        #: frames rendered per pass (the ``lookahead`` option)
        self.lookahead = lookahead
        # two pass buffers: on OpenCL the next pass renders into one while the other is handed out
        self._buffers = [np.empty((lookahead, *self._shape), np.uint8) for _ in range(2 if lookahead > 1 else 0)]
        self._ahead = self._buffers[0] if self._buffers else None
        self._ahead_states: list[dict[str, Any]] = []
        self._ahead_next = 0
        self._in_flight: tuple[Any, list[dict[str, Any]], np.ndarray] | None = None
        self._pass = lookahead
        self.reseed(seed)
        self._project(self._vector(), np.empty(self._shape, np.uint8))  # warm the kernel

    # -- what a mode supplies ----------------------------------------------------------
    _dim: int

    def _setup(self, model) -> None:
        raise NotImplementedError

    def _basis(self, model) -> tuple[np.ndarray, ...]:
        """The rows the frames project through, as blocks of rows stacked (the engine takes them
        so, without a copy into one array): the model's ``basis_name`` attribute."""
        return (getattr(model, self.basis_name),)

    def _vector(self) -> np.ndarray:
        raise NotImplementedError

    def _step(self) -> None:
        raise NotImplementedError

    def _coefficients(self, v: np.ndarray, coef: np.ndarray) -> None:
        raise NotImplementedError

    def _detail_rate(self) -> float:
        """Volume frames the detail advances per played frame: it keeps the model's pace."""
        return 1.0

    def _detail_state(self) -> dict[str, Any]:
        return {"detail_clock": self._detail_clock}

    def _layers(self):
        """The detail layers of the next frame (None without detail)."""
        if self.detail_engine is None:
            return None
        amount = self._detail * np.sqrt(self._intensity)
        return self.detail_engine.layers(self.seed, math.floor(self._detail_clock), amount)

    def _restore_detail(self, state: dict[str, Any]) -> None:
        """The detail's clock from ``state`` (a state without one: the frame index, as it was)."""
        clock = float(state.get("detail_clock", state.get("frame_index", 0)))
        if not np.isfinite(clock):
            raise InvalidArgumentError("state detail_clock must be a finite number")
        self._detail_clock = clock

    # -- controls ----------------------------------------------------------------
    @property
    def bytes_per_frame(self) -> int:
        """The basis and mean read, plus the uint8 frame written (and the detail's reads)."""
        extra = 0 if self.detail_engine is None else self.detail_engine.bytes_per_frame
        return self.engine.bytes_per_frame + extra

    intensity = Control(
        Range(float, 0.0, MAX_INTENSITY),
        1.0,
        "Scale of the driving noise's covariance (0 follows the deterministic prediction).",
    )

    detail = Control(
        Range(float, 0.0, MAX_DETAIL),
        1.0,
        "Scale of the fine detail added to each frame (the part of the clip the projection drops; "
        "0: none, the source's colour range still holds), times sqrt(intensity); no effect on "
        "textures analysed without it.",
    )

    # -- synthesis -----------------------------------------------------------------
    def advance(self, steps: int = 1, *, record: bool = False) -> np.ndarray | None:
        """Run the recursion ``steps`` times without projecting frames.

        With ``record=True`` returns the visited vectors, ``(steps, dim)``.
        """
        steps = check_int("steps", steps, 0)
        self._settle()
        rec = np.empty((steps, self._dim)) if record else None
        for i in range(steps):
            self._step()
            self._detail_clock += self._detail_rate()
            if rec is not None:
                rec[i] = self._vector()
        self.frame_index += steps
        return rec

    def _start(self, out: np.ndarray):
        if self._ahead is not None:
            if self._ahead_next >= len(self._ahead_states):
                if self._in_flight is not None:
                    event, states, buffer = self._in_flight
                    self._in_flight = None
                    if event is not None:
                        event.wait()
                    self._ahead, self._ahead_states, self._ahead_next = buffer, states, 0
                else:
                    self._ahead_states = self._render_ahead(self._ahead, wait=True)[1]
                    self._ahead_next = 0
                if self.ctx is not None:  # the next pass renders while this one is handed out
                    other = self._buffers[1] if self._ahead is self._buffers[0] else self._buffers[0]
                    event, states = self._render_ahead(other, wait=False)
                    self._in_flight = (event, states, other)
            out[...] = self._ahead[self._ahead_next]
            self._ahead_next += 1
            return None
        self._coefficients(self._vector(), self.engine.coef)
        event = self._run(out, wait=False)
        self._step()
        self._detail_clock += self._detail_rate()
        return event

    def _render_ahead(self, buffer: np.ndarray, *, wait: bool):
        """Run the state a pass ahead and project the pass's frames into ``buffer``; the event
        after which they are there (None once they are) and the state before each frame."""
        count = self._pass
        self._pass = min(2 * count, self.lookahead)
        states, layers = [], [] if self.detail_engine is not None else None
        for j in range(count):
            states.append(self._get_state())
            self._coefficients(self._vector(), self.engine.coefs[j])
            if layers is not None:
                layers.append(self._layers())
            self._step()
            self._detail_clock += self._detail_rate()
        dest = buffer if count == self.lookahead else buffer[:count]  # the same array: wrapped once
        return self.engine.run(dest, count=count, layers=layers, wait=wait), states

    def _settle(self) -> None:
        """Discard the frames computed ahead: the player is back after the last frame handed out."""
        with self._lock:
            state = self._delivered()
            if state is None:
                return
            if self._in_flight is not None:
                if self._in_flight[0] is not None:
                    self._in_flight[0].wait()
                self._in_flight = None
            self._set_state(state)
            self._ahead_states, self._ahead_next = [], 0
            self._pass = 1

    def _delivered(self) -> dict[str, Any] | None:
        """The mode's state after the last frame handed out, where frames were computed past it."""
        states, i = self.__dict__.get("_ahead_states"), self.__dict__.get("_ahead_next", 0)
        if states and i < len(states):
            return states[i]
        pending = self.__dict__.get("_in_flight")
        return pending[1][0] if pending is not None else None

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self._controls and self._delivered() is not None:
            self._settle()
        super().__setattr__(name, value)

    def get_state(self) -> dict[str, Any]:
        """As :meth:`Player.get_state`; with look-ahead, the state after the last frame handed out."""
        with self._lock:
            state = super().get_state()
            state.update(self._delivered() or {})
            return state

    def set_state(self, state: dict[str, Any]) -> None:
        self._settle()
        super().set_state(state)

    def reseed(self, seed: int) -> None:
        self._settle()
        super().reseed(seed)

    def _run(self, out: np.ndarray, *, wait: bool = True):
        """Project the engine's coefficients into ``out``, adding the detail where the model has it."""
        layers = self._layers()
        return self.engine.draw(out, layers=None if layers is None else [layers], wait=wait)

    def _render_vector(self, name: str, v: np.ndarray, out: np.ndarray | None) -> np.ndarray:
        """Project an arbitrary vector (checked, named ``name`` in errors); the player does not advance."""
        v = np.asarray(v, dtype=float)
        if v.shape != (self._dim,) or not np.isfinite(v).all():
            raise InvalidArgumentError(f"{name} must be a finite vector of shape ({self._dim},)")
        if out is None:
            out = np.empty(self._shape, np.uint8)
        self._project(v, out)
        return out

    def _project(self, v: np.ndarray, out: np.ndarray) -> None:
        self._coefficients(v, self.engine.coef)
        self._run(out)

    def close(self) -> None:
        """Finish the frames in flight and release the engines and the database."""
        if self.queue is not None:
            self.queue.finish()
        super().close()
