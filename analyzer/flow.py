"""Optical flow for motion-compensated turn-point jumps.

A jump ``i -> j`` crossfades, frame by frame, the path it left with the path it takes: the pairs
``(i + 1 + k, j + k)``, ``k = 0 .. crossfade - 1`` forward and ``k = 1 - crossfade .. 0`` in the
mirror hybrid play takes backward. For each pair the analysis computes the midpoint flow ``f``
(``a(p - f/2)`` matches ``b(p + f/2)``): OpenCV's DIS flow both ways, turned into the flow at
the half-way point by a fixed-point iteration, smoothed over the grid step and stored as int16
in 1/16 pixels on a grid every ``step`` pixels (:class:`~dynatex.tiledb.turnpoints.FlowModel`).
The player warps both frames along it through the crossfade (:mod:`dynatex.player.engines.warp`), and
the analysis measures the double images of exactly that (the player's numpy reference on luma).
"""

from __future__ import annotations

import numpy as np

from ..framestats import LUMA
from ..player.engines.warp import warp_reference
from ..tiledb.turnpoints import FLOW_FRACTION_BITS, FlowModel, flow_grid
from .metrics import DoubleImages

#: Longest side of the flow grid: the step doubles from 4 pixels until the grid fits.
MAX_GRID_SIDE = 128
#: Shortest longer side of the frames the flow is computed on (larger frames are halved down to it).
FLOW_SIDE = 128
#: Shortest side a flow is computed on: OpenCV's DIS crashes the process on frames of 12 pixels or less.
MIN_FLOW_SIDE = 16
#: Farthest frame from ``a`` the flow from ``a`` to ``b`` follows the clip to (see :class:`PairFlows`).
CHAIN_REACH = 12
#: Fixed-point iterations from the flow at ``a`` to the flow at the half-way point.
MIDPOINT_ITERATIONS = 4


def grid_step(height: int, width: int) -> int:
    """The flow grid step for frames of ``height`` x ``width``: 4 pixels (1/4 resolution), doubled
    while the grid's longer side exceeds :data:`MAX_GRID_SIDE`.

    >>> grid_step(240, 240), grid_step(720, 1280)
    (4, 16)
    """
    step = 4
    while max(height, width) / step > MAX_GRID_SIDE:
        step *= 2
    return step


def luma(frames: np.ndarray) -> np.ndarray:
    """``(T, H, W)`` uint8 luma of ``(T, H, W, C)`` uint8 frames (C = 1 or 3)."""
    if frames.shape[-1] == 1:
        return np.ascontiguousarray(frames[..., 0])
    y = frames.astype(np.float32) @ LUMA
    return np.clip(np.rint(y), 0, 255).astype(np.uint8)


def can_flow(height: int, width: int) -> bool:
    """Whether frames of ``height`` x ``width`` are large enough for a flow (:data:`MIN_FLOW_SIDE`).

    >>> can_flow(8, 48), can_flow(64, 64)
    (False, True)
    """
    d = flow_factor(height, width)
    return min(height, width) // d >= MIN_FLOW_SIDE


def flow_factor(height: int, width: int) -> int:
    """Power-of-two reduction of the frames the flow is computed on: the longer side stays at
    least :data:`FLOW_SIDE` pixels.

    >>> flow_factor(240, 240), flow_factor(288, 352), flow_factor(720, 1280)
    (1, 2, 8)
    """
    d = 1
    while max(height, width) / (2 * d) >= FLOW_SIDE:
        d *= 2
    return d


def _remap(field: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """``field`` sampled bilinearly at ``(x + dx, y + dy)`` of every pixel, edges repeated."""
    import cv2

    h, w = field.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    return cv2.remap(field, xx + dx, yy + dy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def to_grid(m: np.ndarray, height: int, width: int, step: int, factor: int) -> np.ndarray:
    """The stored grid ``(Gh, Gw, 2)`` int16 (1/16 px) of a flow ``m`` computed on frames reduced by
    ``factor`` from ``height`` x ``width``: box-smoothed over the step, sampled every ``step`` pixels."""
    import cv2

    h, w = m.shape[:2]
    box = max(1, step // factor) + 1
    m = cv2.blur(m, (box, box), borderType=cv2.BORDER_REPLICATE)
    gh, gw = flow_grid(height, width, step)
    ys = np.minimum(np.rint(np.arange(gh) * step / factor).astype(int), h - 1)
    xs = np.minimum(np.rint(np.arange(gw) * step / factor).astype(int), w - 1)
    grid = m[ys[:, None], xs[None, :]] * (factor << FLOW_FRACTION_BITS)
    return np.clip(np.rint(grid), -32767, 32767).astype(np.int16)


class PairFlows:
    """Midpoint flows of frame pairs of one clip, computed once each (either order).

    Frames a jump pairs are far apart in the clip and often far apart in motion too (that is when a
    plain crossfade shows two objects); a flow estimator alone finds little of a large motion of a
    thin object. So the flow from ``a`` to ``b`` follows the clip itself: from ``a`` along the
    flows between consecutive frames (small, reliable motions) to the frame ``c`` within
    ``reach`` frames of ``a`` that looks most like ``b``, then the flow from ``c`` to ``b``
    (``c = a`` is a direct flow). Its midpoint form comes from a fixed-point iteration.
    """

    def __init__(self, frames: np.ndarray, reach: int = CHAIN_REACH) -> None:
        import cv2

        self.grey = luma(frames)
        t, h, w = self.grey.shape
        self.step = grid_step(h, w)
        self.step_log2 = self.step.bit_length() - 1
        self.factor = flow_factor(h, w)
        self.reach = reach
        size = (max(1, w // self.factor), max(1, h // self.factor))
        self._small = [cv2.resize(g, size, interpolation=cv2.INTER_AREA) if self.factor > 1 else g for g in self.grey]
        s = min(1.0, 48 / max(h, w))
        thumb = (max(1, round(w * s)), max(1, round(h * s)))
        self._thumbs = np.stack([cv2.resize(g, thumb, interpolation=cv2.INTER_AREA) for g in self.grey]).astype(
            np.float32
        )
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        self._steps: dict[tuple[int, int], np.ndarray] = {}
        self._flows: dict[tuple[int, int], np.ndarray] = {}

    def get(self, a: int, b: int) -> np.ndarray:
        """The grid of the flow from frame ``a`` toward frame ``b``."""
        if (b, a) in self._flows:
            return -self._flows[(b, a)]
        if (a, b) not in self._flows:
            f = self.flow(a, b)
            m = f.copy()
            for _ in range(MIDPOINT_ITERATIONS):  # m(p) = f(p - m(p) / 2): the flow at the half-way point
                m = _remap(f, -0.5 * m[..., 0], -0.5 * m[..., 1])
            self._flows[(a, b)] = to_grid(m, *self.grey.shape[1:], self.step, self.factor)
        return self._flows[(a, b)]

    def flow(self, a: int, b: int) -> np.ndarray:
        """The flow ``f`` from ``a`` to ``b`` on the reduced frames: ``a(p)`` matches ``b(p + f(p))``."""
        t = len(self.grey)
        lo, hi = max(0, a - self.reach), min(t - 1, a + self.reach)
        d = np.sum((self._thumbs[lo : hi + 1] - self._thumbs[b]) ** 2, axis=(1, 2))
        c = lo + int(np.argmin(d))
        acc = np.zeros(self._small[0].shape + (2,), np.float32)
        step = 1 if c > a else -1
        for k in range(a, c, step):  # a -> c along the clip: each step's flow where the tracked point is
            acc += _remap(self._step(k, k + step), acc[..., 0], acc[..., 1])
        if c != b:
            acc += _remap(self._dis.calc(self._small[c], self._small[b], None), acc[..., 0], acc[..., 1])
        return acc

    def _step(self, k: int, n: int) -> np.ndarray:
        if (k, n) not in self._steps:
            self._steps[(k, n)] = self._dis.calc(self._small[k], self._small[n], None)
        return self._steps[(k, n)]

    def model(self, pairs) -> FlowModel:
        """The stored part for the frame ``pairs`` (each once, in either order)."""
        pairs = sorted({(min(a, b), max(a, b)) for a, b in pairs})
        gh, gw = flow_grid(*self.grey.shape[1:], self.step)
        flows = np.stack([self.get(a, b) for a, b in pairs]) if pairs else np.zeros((0, gh, gw, 2), np.int16)
        return FlowModel(pairs=np.array(pairs, np.int32).reshape(-1, 2), flows=flows, step=self.step)


def crossfade_pairs(i: int, j: int, crossfade: int, t: int) -> list[tuple[int, int, int]]:
    """``(old, new, weight of new in 256ths)`` of every crossfaded frame of jump ``i -> j``: forward
    (``j + m - 1`` over ``i + m``) and the mirror backward (``i + 2 - m`` over ``j + 1 - m``),
    ``m = 1 .. crossfade``, weights ``round(256 m / (crossfade + 1))`` as the player's; pairs that
    leave the clip's ``t`` frames are not shown and left out.

    >>> crossfade_pairs(10, 3, 2, 20)
    [(11, 3, 85), (12, 4, 171), (3, 11, 85), (2, 10, 171)]
    """
    out = []
    for forward in (True, False):
        for m in range(1, crossfade + 1):
            old, new = (i + m, j + m - 1) if forward else (j + 1 - m, i + 2 - m)
            if 0 <= old < t and 0 <= new < t:
                out.append((old, new, round(256 * m / (crossfade + 1))))
    return out


def warped_crossfade_ghost(
    flows: PairFlows, ghosts: DoubleImages, i: np.ndarray, j: np.ndarray, crossfade: int
) -> np.ndarray:
    """The largest double image of the motion-compensated crossfaded frames of each jump
    ``i[k] -> j[k]`` (forward and mirrored, as :func:`crossfade_pairs`), ``(len(i),)``: each frame
    drawn with the player's numpy reference on the luma (frames larger than the flow's working
    size on the reduced luma with the grid scaled alike, then enlarged: the measure looks at
    thumbnails of at most 96 pixels anyway)."""
    import cv2

    t, h, w = flows.grey.shape
    r = flows.factor
    grey = np.stack(flows._small)[..., None]
    step_log2 = max(0, flows.step_log2 - (r.bit_length() - 1))
    grid = flow_grid(grey.shape[1], grey.shape[2], 1 << step_log2)
    out = np.zeros(len(i))
    scratch = np.empty(grey.shape[1:], np.uint8)
    for k, (a, b) in enumerate(zip(np.asarray(i).tolist(), np.asarray(j).tolist())):
        drawn = []
        for old, new, wgt in crossfade_pairs(a, b, crossfade, t):
            f = flows.get(old, new)
            if r > 1:
                f = np.rint(f[: grid[0], : grid[1]] / r).astype(np.int16)
                f = np.pad(f, ((0, grid[0] - f.shape[0]), (0, grid[1] - f.shape[1]), (0, 0)), mode="edge")
            warp_reference(grey, old, new, 256 - wgt, wgt, f, step_log2, scratch)
            drawn.append(
                scratch[..., 0] if r == 1 else cv2.resize(scratch[..., 0], (w, h), interpolation=cv2.INTER_LINEAR)
            )
            drawn[-1] = drawn[-1].copy()
        if drawn:
            out[k] = ghosts.of(np.stack(drawn)).max()
    return out
