"""Mode ``turnpoints``: endless playback of the source frames themselves, reversing at
turn points (Van Haevre & Van Reeth) and jumping along video-texture transitions.

The walk over source frames is host work (a few microseconds a step): at a turn point
playback reverses with an adaptive probability (the seed's eq. 7: it starts at half the
maximum, drops by ``increment`` after a turn and rises by ``increment`` after a pass, so
the whole clip gets used); elsewhere it may take a transition. The outermost turn points
always reverse when playback heads outward, and forward-only playback always jumps at the
exit frame, so the walk never reaches a dead end. Hybrid playback takes no jump that starts
before the first turn point heading forward (or beyond the last heading backward): it would
replay that lead-in, for ever where the jump is certain.

Frames are kept in memory on the device: ``T * ceil(H*W*3 / 64) * 64`` bytes (grey clips
are expanded to RGB), e.g. 7.4 MB for the 43-frame 240x240 pendulum clip, 321 MB for 116
frames at 1280x720. A frame that is one stored frame is a single device-to-host copy
straight into the caller's buffer; a crossfade (after a jump) or a fractional speed
blends two (or up to four) frames with one kernel launch in exact integer arithmetic,
so the numpy reference gives identical bytes. Where the model stores the optical flow of a
jump's frame pairs, the crossfade warps both frames toward each other along it
(:mod:`~dynatex.player.engines.warp`), so a moving object slides instead of showing twice.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import MAX_COUNT, Choice, Range, check_float, check_int
from ...errors import InvalidArgumentError
from ...params import Param
from ...tiledb.turnpoints import TurnPointModel
from ..base import Player, rng_from_state
from ..controls import Capabilities, Control
from ..engines import open_engine
from ..engines.warp import WarpBlend
from ..loop import repeats

PLAYBACKS = ("hybrid", "turns", "jumps")
SPEED_RANGE = (0.0, 4.0)
MAX_CROSSFADE = 16
EVENT_NONE, EVENT_TURN, EVENT_JUMP = 0, 1, 2


class TurnPointPlayer(Player):
    """Endless frames from a texture's ``turnpoints`` tables and stored frames.

    Observables: ``source_index`` (the walk's source frame of the last output frame),
    ``last_event`` (0 none, 1 turn, 2 jump, 3 both), ``last_sources`` ((frame, weight/256)
    pairs), ``probabilities`` (current reversal probabilities), :meth:`advance` (the walk
    without rendering).

    Examples
    --------
    >>> with TurnPointPlayer("pendulum.h5", seed=1) as p:   # doctest: +SKIP
    ...     frame = p.next_frame()
    ...     p.source_index, p.last_event
    """

    mode = "turnpoints"
    method = "turnpoints"
    options = (
        Param(
            "playback",
            Choice(*PLAYBACKS),
            "hybrid",
            "Turn points and transitions (hybrid), turn points only (turns, the seed) or transitions only "
            "(jumps: classic video textures, forward only).",
        ),
        Param("start", Range(int, 0, MAX_COUNT), 0, "Source frame of the first output frame (played forward)."),
    )
    capabilities = Capabilities(needs_frames=True, native_loop=True)

    checked_first = ("playback",)

    def _open(self, *, seed: int, playback: str, start: int) -> None:
        self._setup(self.texture.read(self.method), playback, seed, start)

    # -- setup -----------------------------------------------------------------------
    def _setup(self, model: TurnPointModel, playback: str, seed: int, start: int) -> None:
        src = self.texture.source
        self.model = model
        self.playback = playback
        t = model.n_frames
        self.n_frames = t
        self._shape = (src.height, src.width, self.format.bytes)
        self._a, self._z = model.first_turn, model.last_turn
        self._p_max = model.p_max.copy()
        self._is_turn = np.zeros(t, bool)
        self._is_turn[model.turn_points] = True
        if playback == "jumps" and model.src.size == 0:
            raise InvalidArgumentError(
                "playback='jumps' needs transitions, and this texture has none; use 'hybrid' or 'turns'"
            )
        self._fwd, self._bwd = self._tables(model)
        start = check_int("start", start, 0, t - 1)
        if playback == "jumps" and start > model.exit_frame:
            raise InvalidArgumentError(
                f"start must be at most the exit frame {model.exit_frame} for playback='jumps', not {start}"
            )
        if playback != "jumps" and start > self._z:
            raise InvalidArgumentError(f"start must be at most the last turn point {self._z}, not {start}")
        self.reseed(seed)
        self._reset_walk(start)

        store = self.texture.frames()
        frames = store.read()
        if frames.shape[-1] == 1:
            frames = np.repeat(frames, 3, axis=-1)
        self.engine = open_engine("blend", frames, ctx=self.ctx, queue=self.queue, format=self.format)
        del frames
        if model.flow is not None and len(model.flow.pairs):  # motion-compensated jump crossfades
            self.engine = WarpBlend(self.engine, model.flow, ctx=self.ctx, queue=self.queue)
        #: bytes the stored frames occupy on the device (or in host memory with numpy)
        self.memory_bytes = self.engine.memory_bytes
        self._warm()

    def _tables(self, model: TurnPointModel):
        """Per source frame: (destinations, cumulative probabilities) forward and backward."""
        t = model.n_frames
        empty = (np.zeros(0, np.int64), np.zeros(0))
        fwd = [empty] * t
        bwd = [empty] * t
        if self.playback == "turns":
            return fwd, bwd
        s, d, p = model.src.astype(np.int64), model.dst.astype(np.int64), model.prob
        if self.playback == "hybrid":
            # Heading forward beyond the last turn: a dead end. From before the first turn (the
            # lead-in, played once) back into it: the walk would replay it, for ever where the
            # jump is certain (an exit frame's), never reaching the turns; mirrored alike.
            ok = (d <= self._z) & (s >= self._a)
            fs, fd, fp = s[ok], d[ok], p[ok]
            bs, bd = d + 1, s + 1  # the mirror of i -> j played backward
            ok = (bd >= self._a) & (bs < t) & (bs <= self._z)
            bs, bd, bp = bs[ok], bd[ok], p[ok]
        else:
            fs, fd, fp = s, d, p
            bs = bd = bp = np.zeros(0)
        for table, ss, dd, pp in ((fwd, fs, fd, fp), (bwd, bs, bd, bp)):
            for i in np.unique(ss).astype(np.int64):
                sel = ss == i
                probs = pp[sel]
                total = probs.sum()
                if total > 1:
                    probs = probs / total
                cum = np.cumsum(probs)
                if self.playback == "jumps" and i == model.exit_frame:
                    cum[-1] = np.inf  # always jump at the exit frame
                table[int(i)] = (dd[sel].astype(np.int64), cum)
        return fwd, bwd

    def _warm(self) -> None:
        scratch = np.empty(self._shape, np.uint8)
        last = self.n_frames - 1
        self._compose(((0, 128), (last, 128)), scratch)
        self._compose(((0, 64), (last, 64), (0, 64), (last, 64)), scratch)
        self._compose(((0, 256),), scratch)

    # -- controls ----------------------------------------------------------------------
    @property
    def bytes_per_frame(self) -> int:
        """Bytes a frame moves at speed 1 between jumps: one stored frame read, the output written."""
        return self.engine.bytes_per_frame

    speed = Control(
        Range(float, *SPEED_RANGE),
        1.0,
        "Source frames advanced per output frame; fractional speeds blend neighbouring frames.",
    )
    crossfade = Control(
        Range(int, 0, MAX_CROSSFADE), 4, "Frames over which a jump is crossfaded with the path it left (0: cut)."
    )
    increment = Control(Range(float, 0.0, 1.0), 0.1, "The eq. 7 step of the adaptive reversal probabilities.")

    @property
    def probabilities(self) -> np.ndarray:
        """Current reversal probability of every source frame (0 where there is no turn point)."""
        return self._p.copy()

    # -- the walk ------------------------------------------------------------------------
    def _reset_walk(self, start: int) -> None:
        self._pos, self._dir = int(start), 1
        self._p = self._p_max / 2.0  # eq. 6
        self._p[[self._a, self._z]] = 1.0
        self._old: list[int] | None = None  # crossfade: [old frame, old direction, k]
        self.dead_ends = 0
        self._phase = 0.0
        first = (self._pos, ((self._pos, 1.0),), EVENT_NONE)
        self._disp = [first, self._walk_step()]
        self._pending = EVENT_NONE
        self.source_index = self._pos
        self.last_event = EVENT_NONE
        self.last_sources: tuple[tuple[int, int], ...] = ((self._pos, 256),)

    def _walk_step(self) -> tuple[int, tuple[tuple[int, float], ...], int]:
        """Advance the walk one source frame: (frame, blend pairs, event)."""
        i, d = self._pos, self._dir
        event = EVENT_NONE
        nxt = None
        if self.playback != "jumps" and self._is_turn[i]:
            if (i == self._a and d < 0) or (i == self._z and d > 0):
                turn = True  # outermost turn heading outward: always
            elif (i == self._a and d > 0) or (i == self._z and d < 0):
                turn = False  # turning here would head outward
            else:
                turn = bool(self._rng.random() < self._p[i])
                inc = self._increment  # eq. 7
                self._p[i] = max(self._p[i] - inc, 0.0) if turn else min(self._p[i] + inc, self._p_max[i])
            if turn:
                d = -d
                nxt = i + d
                event = EVENT_TURN
        if nxt is None and self.playback != "turns":
            dsts, cum = (self._fwd if d > 0 else self._bwd)[i]
            if dsts.size:
                k = int(np.searchsorted(cum, self._rng.random(), side="right"))
                if k < dsts.size:
                    nxt = int(dsts[k])
                    event = EVENT_JUMP
                    self._old = [i + d, d, 1]
        if nxt is None:
            nxt = i + d
        if not 0 <= nxt < self.n_frames:  # never happens with valid tables
            self.dead_ends += 1
            d = -d
            nxt = i + d
        self._pos, self._dir = nxt, d
        pairs: tuple[tuple[int, float], ...] = ((nxt, 1.0),)
        old = self._old
        if old is not None:
            o, od, k = old
            n_fade = self._crossfade
            if k <= n_fade and 0 <= o < self.n_frames:
                w = k / (n_fade + 1)
                pairs = ((nxt, w), (o, 1.0 - w))
                old[0], old[2] = o + od, k + 1
            else:
                self._old = None
        return nxt, pairs, event

    def _advance_display(self) -> None:
        """Move the output clock by ``speed`` source frames."""
        self._phase += self._speed
        while self._phase >= 1.0:
            self._phase -= 1.0
            self._disp.pop(0)
            self._disp.append(self._walk_step())
            self._pending |= self._disp[0][2]

    def _current(self) -> tuple[tuple[int, int], ...]:
        """Integer blend weights (summing to 256) of the output frame at the current phase."""
        f = self._phase
        acc: dict[int, float] = {}
        for (_, pairs, _), wd in ((self._disp[0], 1.0 - f), (self._disp[1], f)):
            if wd > 0:
                for frame, w in pairs:
                    acc[frame] = acc.get(frame, 0.0) + wd * w
        return _fixed_point(acc)

    def advance(self, count: int, *, record: bool = True):
        """Run ``count`` output frames' worth of the walk without rendering.

        Returns ``(source_index, event)`` arrays of length ``count`` when ``record``.
        """
        count = check_int("count", count, 0)
        idx = np.empty(count, np.int32) if record else None
        ev = np.empty(count, np.int8) if record else None
        for n in range(count):
            self._emit()
            if record:
                idx[n] = self.source_index
                ev[n] = self.last_event
            self._advance_display()
        self.frame_index += count
        return (idx, ev) if record else None

    def _emit(self) -> tuple[tuple[int, int], ...]:
        # The output frame shows walk step disp[0] (blended towards disp[1] by the phase); its
        # event is every turn or jump the walk made since the previous output frame.
        sources = self._current()
        self.last_sources = sources
        self.source_index = self._disp[0][0]
        self.last_event = self._pending
        self._pending = EVENT_NONE
        return sources

    def _start(self, out: np.ndarray):
        event = self._compose(self._emit(), out, wait=False)
        self._advance_display()
        return event

    def _compose(self, sources: tuple[tuple[int, int], ...], out: np.ndarray, *, wait: bool = True):
        """``out`` = the weighted sum of ``sources`` ((frame, weight in 256ths) pairs); returns
        None once it is there, or (``wait=False``) the event after which it is."""
        return self.engine.draw(out, sources, wait=wait)

    # -- state ---------------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {
            "playback": self.playback,
            "pos": self._pos,
            "dir": self._dir,
            "p": self._p.copy(),
            "old": None if self._old is None else list(self._old),
            "phase": self._phase,
            "disp": [(f, tuple(pairs), e) for f, pairs, e in self._disp],
            "pending": self._pending,
            "rng": self._rng.bit_generator.state,
            "seed": self.seed,
        }

    def _set_state(self, state: dict[str, Any]) -> None:
        if state["playback"] != self.playback:
            raise InvalidArgumentError(f"state is for playback {state['playback']!r}, not {self.playback!r}")
        t = self.n_frames
        pos = check_int("state pos", state["pos"], 0, t - 1)
        direction = int(state["dir"])
        if direction not in (-1, 1):
            raise InvalidArgumentError("state dir must be -1 or 1")
        p = np.asarray(state["p"], dtype=float)
        if p.shape != (t,) or not np.isfinite(p).all() or p.min() < 0 or p.max() > 1:
            raise InvalidArgumentError(f"state p must be ({t},) probabilities")
        disp = [(int(f), tuple((int(a), float(w)) for a, w in pairs), int(e)) for f, pairs, e in state["disp"]]
        if len(disp) != 2 or any(not 0 <= a < t for _, pairs, _ in disp for a, _ in pairs):
            raise InvalidArgumentError("state disp is invalid")
        rng = rng_from_state(state["rng"])
        phase = check_float("state phase", state["phase"], 0.0, 1.0)
        old = None if state["old"] is None else [int(v) for v in state["old"]]
        pending = int(state["pending"])
        self._pos, self._dir, self._p, self._disp, self._phase = pos, direction, p.copy(), disp, phase
        self._old, self._pending = old, pending
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))

    # -- loop -----------------------------------------------------------------------
    def _native_loop(self, count: int | None, keep_pace: bool) -> tuple[np.ndarray, str, float]:
        """The longest swing between two consecutive turn points and back, a path that returns to
        its start, resampled from the stored frames, neighbours blended
        (:func:`dynatex.player.loop.loop_frames`)."""
        if not self.texture.has_frames:
            raise InvalidArgumentError("a turnpoints loop needs the stored source frames")
        source = self.texture.frames().read()
        if source.shape[-1] == 1:
            source = np.repeat(source, 3, axis=-1)
        turns = np.asarray(self.model.turn_points)
        i = int(np.argmax(np.diff(turns)))
        a, b = int(turns[i]), int(turns[i + 1])
        period = 2 * (b - a)
        n, loops = repeats(period, count, keep_pace)
        pos = (np.arange(n) * (period * loops / n)) % period
        pos = np.where(pos <= b - a, a + pos, a + period - pos)  # a -> b -> back toward a
        lo = np.floor(pos).astype(int)
        hi = np.minimum(lo + 1, len(source) - 1)
        w = (pos - lo)[:, None, None, None]
        frames = np.rint((1 - w) * source[lo] + w * source[hi]).astype(np.uint8)
        if frames.shape[1:] != tuple(self.shape):  # the player's pixel format (e.g. BGRA)
            frames = self.format.from_rgb(frames)
        how = f"swing between turn points {a} and {b} and back ({period} source frames), {loops} time(s)"
        return frames, how, period * loops / n


def _fixed_point(weights: dict[int, float]) -> tuple[tuple[int, int], ...]:
    """Float weights (summing to 1) as integers summing to 256, largest remainders rounded up,
    at most four terms, heaviest first."""
    items = sorted(((w, f) for f, w in weights.items() if w > 0), reverse=True)[:4]
    total = sum(w for w, _ in items)
    scaled = [(256.0 * w / total, f) for w, f in items]
    ints = [int(s) for s, _ in scaled]
    rest = 256 - sum(ints)
    order = sorted(range(len(scaled)), key=lambda k: scaled[k][0] - ints[k], reverse=True)
    for k in order[:rest]:
        ints[k] += 1
    return tuple((f, w) for (_, f), w in zip(scaled, ints) if w > 0)
