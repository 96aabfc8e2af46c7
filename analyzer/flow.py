"""Optical flow for motion-compensated turn-point jumps.

A jump ``i -> j`` crossfades, frame by frame, the path it left with the path it takes: the pairs
``(i + 1 + k, j + k)``, ``k = 0 .. crossfade - 1`` forward and ``k = 1 - crossfade .. 0`` in the
mirror hybrid play takes backward. For each pair the analysis computes the midpoint flow ``f``
(``a(p - f/2)`` matches ``b(p + f/2)``): OpenCV's DIS flow both ways, turned into the flow at
the half-way point by a fixed-point iteration, smoothed over the grid step and stored as int16
in 1/16 pixels on a grid every ``step`` pixels (:class:`~dynatex.tiledb.turnpoints.FlowModel`).
The player warps both frames along it through the crossfade (:mod:`dynatex.player.warp`), and
the analysis measures the double images of exactly that (the player's numpy reference on luma).
"""

from __future__ import annotations

import numpy as np

from ..player.warp import warp_reference
from ..tiledb.turnpoints import FLOW_FRACTION_BITS, FlowModel, flow_grid
from .metrics import DoubleImages

#: Longest side of the flow grid: the step doubles from 4 pixels until the grid fits.
MAX_GRID_SIDE = 128
#: Shortest longer side of the frames the flow is computed on (larger frames are halved down to it).
FLOW_SIDE = 200
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
    y = frames.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    return np.clip(np.rint(y), 0, 255).astype(np.uint8)


def flow_factor(height: int, width: int) -> int:
    """Power-of-two reduction of the frames the flow is computed on: the longer side stays at
    least :data:`FLOW_SIDE` pixels.

    >>> flow_factor(240, 240), flow_factor(720, 1280)
    (1, 4)
    """
    d = 1
    while max(height, width) / (2 * d) >= FLOW_SIDE:
        d *= 2
    return d


def midpoint_flow(a: np.ndarray, b: np.ndarray, step: int, factor: int = 1) -> np.ndarray:
    """The stored grid ``(Gh, Gw, 2)`` int16 of the midpoint flow from luma frame ``a`` to ``b``
    (both ``(H, W)`` uint8), computed on frames reduced by ``factor`` (:func:`flow_factor`)."""
    import cv2

    full = a.shape
    if factor > 1:
        size = (max(1, full[1] // factor), max(1, full[0] // factor))
        a = cv2.resize(a, size, interpolation=cv2.INTER_AREA)
        b = cv2.resize(b, size, interpolation=cv2.INTER_AREA)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    fwd = dis.calc(a, b, None)  # a(p) ~ b(p + fwd(p))
    bwd = dis.calc(b, a, None)  # b(p) ~ a(p + bwd(p))
    h, w = a.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    m = 0.5 * (fwd - bwd)
    for _ in range(MIDPOINT_ITERATIONS):
        half = 0.5 * m
        at_a = cv2.remap(fwd, xx - half[..., 0], yy - half[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        at_b = cv2.remap(bwd, xx + half[..., 0], yy + half[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        m = 0.5 * (at_a - at_b)
    box = max(1, step // factor) + 1
    m = cv2.blur(m, (box, box), borderType=cv2.BORDER_REPLICATE)
    gh, gw = flow_grid(full[0], full[1], step)
    ys = np.minimum(np.rint(np.arange(gh) * step / factor).astype(int), h - 1)
    xs = np.minimum(np.rint(np.arange(gw) * step / factor).astype(int), w - 1)
    grid = m[ys[:, None], xs[None, :]] * (factor << FLOW_FRACTION_BITS)
    return np.clip(np.rint(grid), -32767, 32767).astype(np.int16)


class PairFlows:
    """Midpoint flows of frame pairs of one clip, computed once each (either order)."""

    def __init__(self, frames: np.ndarray) -> None:
        self.grey = luma(frames)
        h, w = self.grey.shape[1:]
        self.step = grid_step(h, w)
        self.step_log2 = self.step.bit_length() - 1
        self.factor = flow_factor(h, w)
        self._flows: dict[tuple[int, int], np.ndarray] = {}

    def get(self, a: int, b: int) -> np.ndarray:
        """The grid of the flow from frame ``a`` toward frame ``b``."""
        if (b, a) in self._flows:
            return -self._flows[(b, a)]
        if (a, b) not in self._flows:
            self._flows[(a, b)] = midpoint_flow(self.grey[a], self.grey[b], self.step, self.factor)
        return self._flows[(a, b)]

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
    drawn with the player's numpy reference on the luma."""
    t = len(flows.grey)
    grey = flows.grey[..., None]
    out = np.zeros(len(i))
    scratch = np.empty(grey.shape[1:], np.uint8)
    for k, (a, b) in enumerate(zip(np.asarray(i).tolist(), np.asarray(j).tolist())):
        drawn = []
        for old, new, w in crossfade_pairs(a, b, crossfade, t):
            warp_reference(grey, old, new, 256 - w, w, flows.get(old, new), flows.step_log2, scratch)
            drawn.append(scratch[..., 0].copy())
        if drawn:
            out[k] = ghosts.of(np.stack(drawn)).max()
    return out
