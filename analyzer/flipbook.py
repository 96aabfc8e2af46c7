"""Flipbooks for game engines: a colour atlas, a motion-vector atlas and the values engines need.

A flipbook is a grid atlas of frames, row-major from the top-left. Its motion-vector atlas
holds, in cell ``k``, the motion of frame ``k``: the mean of the optical flows from frame
``k - 1`` to ``k`` and from ``k`` to ``k + 1`` (wrapping: the flow from the last frame to the
first is computed too, so that a loop blends across the wrap; a clip that is not a loop uses
the one flow its first and last frames have), in the tile's UV units with ``v`` up, encoded
``byte = 127.5 + 127.5 * flow / strength`` in R (u) and G (v): centred at 128, linear (not
sRGB). A shader decodes ``rg * 2 - 1`` and multiplies by the strength (in atlas UV units when
it offsets atlas coordinates: ``strength / cols``), as Unity VFX Graph's "Flipbook Motion
Blend" does: frame ``k`` sampled at ``uv - blend * mv_k``, frame ``k + 1`` at
``uv + (1 - blend) * mv_{k+1}``, mixed by ``blend``: each frame's own motion is used both
ways, which is why a cell holds the motion *at* its frame rather than the flow to the next.
:func:`shader_blend` is that shader in numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgumentError

#: Farneback optical-flow parameters (pyramid scale, levels, window, iterations, poly_n, poly_sigma).
FLOW_PARAMS = (0.5, 4, 15, 3, 5, 1.2)
#: Percentile of the vectors' components that the encoding's strength covers.
STRENGTH_PERCENTILE = 99.9
#: Largest atlas side engines import without complaint.
MAX_ATLAS_SIDE = 16384


@dataclass(frozen=True)
class Grid:
    """Layout of ``frames`` frames of ``tile`` (height, width) pixels in ``cols`` x ``rows`` cells."""

    cols: int
    rows: int
    tile: tuple[int, int]
    frames: int

    @property
    def atlas_shape(self) -> tuple[int, int]:
        return self.rows * self.tile[0], self.cols * self.tile[1]

    def cell(self, k: int) -> tuple[slice, slice]:
        """Rows and columns of frame ``k``'s cell in the atlas."""
        r, c = divmod(k, self.cols)
        th, tw = self.tile
        return slice(r * th, (r + 1) * th), slice(c * tw, (c + 1) * tw)


def _pow2(v: float) -> int:
    return 1 << max(0, round(math.log2(max(v, 1.0))))


def choose_grid(
    frames: int,
    frame_shape: tuple[int, int],
    *,
    cols: int | None = None,
    rows: int | None = None,
    tile: tuple[int, int] | None = None,
    pow2: bool = True,
    packed: bool = False,
) -> Grid:
    """The grid for ``frames`` frames of ``frame_shape`` (H, W).

    ``packed``: the grid with the fewest empty cells (none when ``frames`` has a factor pair)
    whose atlas is at most 2:1, the most square of those, and cells of the frame's own shape
    (scaled down, aspect kept, when the atlas would pass :data:`MAX_ATLAS_SIDE`): for engines
    that take any grid and frame count (Unity's VFX Graph and particle texture sheets, Unreal's
    SubUV, Godot's particle frames). Otherwise, with ``pow2``, the grid is the smallest
    power-of-two one holding the frames (columns >= rows, a square grid for 4, 16, 64... frames)
    and each tile side is the power of two nearest the frame's, so the atlas is a power of two on
    both sides; without, the same near-square grid of frame-sized tiles. ``tile`` sets the tile (H, W).

    Examples
    --------
    >>> choose_grid(64, (288, 352))
    Grid(cols=8, rows=8, tile=(256, 256), frames=64)
    >>> choose_grid(22, (240, 240)).atlas_shape
    (1024, 2048)
    >>> choose_grid(80, (288, 352), packed=True)      # 80 cells, cells of the frame's aspect
    Grid(cols=8, rows=10, tile=(288, 352), frames=80)
    """
    if frames < 1:
        raise InvalidArgumentError(f"a flipbook needs at least one frame, not {frames}")
    if packed and tile is None:
        tile = tuple(frame_shape)
    if cols is None and rows is None:
        if packed:
            cols, rows = _packed_grid(frames, tile)
        else:
            rows = 1 << (max(0, math.ceil(math.log2(frames))) // 2)
            cols = 1 << math.ceil(math.log2(math.ceil(frames / rows))) if pow2 else math.ceil(frames / rows)
    elif cols is None:
        cols = math.ceil(frames / rows)
    elif rows is None:
        rows = math.ceil(frames / cols)
    if cols * rows < frames:
        raise InvalidArgumentError(f"a {cols}x{rows} grid holds {cols * rows} frames, fewer than {frames}")
    if tile is None:
        h, w = frame_shape
        tile = (_pow2(h), _pow2(w)) if pow2 else (h, w)
    th, tw = int(tile[0]), int(tile[1])
    if packed:  # shrink the frame-shaped cells, keeping their aspect, until the atlas fits
        scale = min(1.0, MAX_ATLAS_SIDE / (rows * th), MAX_ATLAS_SIDE / (cols * tw))
        th, tw = max(1, math.floor(th * scale)), max(1, math.floor(tw * scale))
    if rows * th > MAX_ATLAS_SIDE or cols * tw > MAX_ATLAS_SIDE:
        raise InvalidArgumentError(
            f"a {cols}x{rows} atlas of {tw}x{th} tiles is {cols * tw}x{rows * th} pixels, more than "
            f"{MAX_ATLAS_SIDE} on a side: use fewer frames or a smaller tile"
        )
    return Grid(int(cols), int(rows), (th, tw), int(frames))


def _packed_grid(frames: int, tile: tuple[int, int]) -> tuple[int, int]:
    """(cols, rows) of :func:`choose_grid`'s packed rule for cells of ``tile`` (H, W)."""
    th, tw = tile
    best: tuple[tuple, int, int] | None = None
    for rows in range(1, frames + 1):
        cols = math.ceil(frames / rows)
        if (cols - 1) * rows >= frames:
            continue  # a column would be empty
        skew = abs(math.log((cols * tw) / (rows * th)))
        key = (skew > math.log(2) + 1e-9, cols * rows - frames, skew)
        if best is None or key < best[0]:
            best = (key, cols, rows)
    assert best is not None
    return best[1], best[2]


def packing(grid: Grid, frame_shape: tuple[int, int], rule: str) -> dict:
    """The sidecar's account of how ``grid`` packs frames of ``frame_shape`` (H, W): empty cells,
    frame and cell aspect (width / height), whether the atlas is a power of two."""
    h, w = frame_shape
    th, tw = grid.tile
    ah, aw = grid.atlas_shape
    cells = grid.cols * grid.rows

    def is_pow2(v: int) -> bool:
        return v & (v - 1) == 0

    return {
        "rule": rule,
        "cells": cells,
        "empty_cells": cells - grid.frames,
        "empty_share": round((cells - grid.frames) / cells, 4),
        "frame_aspect": round(w / h, 4),
        "cell_aspect": round(tw / th, 4),
        "aspect_change": round((tw / th) / (w / h) - 1, 4),
        "cell_scale": [round(th / h, 4), round(tw / w, 4)],
        "power_of_two": is_pow2(ah) and is_pow2(aw),
    }


def fit(frame: np.ndarray, tile: tuple[int, int]) -> np.ndarray:
    """``frame`` resized to ``tile`` (H, W): area averaging when shrinking, bilinear when growing."""
    import cv2

    th, tw = tile
    if frame.shape[:2] == (th, tw):
        return np.ascontiguousarray(frame)
    shrink = th * tw < frame.shape[0] * frame.shape[1]
    return cv2.resize(frame, (tw, th), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def color_atlas(tiles: np.ndarray, grid: Grid) -> np.ndarray:
    """``(rows*th, cols*tw, C)`` atlas of ``tiles`` ``(N, th, tw, C)``, row-major from the top-left;
    cells past the last frame stay black."""
    atlas = np.zeros(grid.atlas_shape + tiles.shape[3:], np.uint8)
    for k, t in enumerate(tiles):
        atlas[grid.cell(k)] = t
    return atlas


def optical_flow(tiles: np.ndarray, *, wrap: bool = True) -> np.ndarray:
    """Farneback flow ``(N, th, tw, 2)`` in pixels (x right, y down) from each tile to the next;
    the last entry is the flow from the last tile to the first (zero unless ``wrap``)."""
    import cv2

    grey = [cv2.cvtColor(t, cv2.COLOR_RGB2GRAY) if t.ndim == 3 else t for t in tiles]
    n = len(grey)
    flow = np.zeros(tiles.shape[:3] + (2,), np.float32)
    for k in range(n if wrap else n - 1):
        flow[k] = cv2.calcOpticalFlowFarneback(grey[k], grey[(k + 1) % n], None, *FLOW_PARAMS, 0)
    return flow


def frame_motion(flow: np.ndarray, *, wrap: bool = True) -> np.ndarray:
    """Motion at each frame: the mean of the flow into it and the flow out of it (see the module)."""
    into = np.roll(flow, 1, axis=0)
    motion = (into + flow) / 2
    if not wrap and len(flow) > 1:
        motion[0], motion[-1] = flow[0], flow[-2]
    return motion


def flow_to_uv(flow: np.ndarray) -> np.ndarray:
    """Pixel flow (x right, y down) as tile UV offsets (u right, v up)."""
    th, tw = flow.shape[-3:-1]
    return np.stack([flow[..., 0] / tw, -flow[..., 1] / th], -1)


def encode_vectors(uv: np.ndarray, strength: float | None = None) -> tuple[np.ndarray, float]:
    """RG bytes of UV offsets and the strength they are scaled by (default: the 99.9th percentile
    of the offsets' components, so that a few wild flow vectors do not coarsen the 8 bits for
    all; larger ones are clipped)."""
    if strength is None:
        strength = float(np.percentile(np.abs(uv), STRENGTH_PERCENTILE)) if uv.size else 0.0
    strength = max(strength, 1e-6)
    rg = np.clip(np.rint(127.5 + 127.5 * uv / strength), 0, 255).astype(np.uint8)
    return rg, strength


def decode_vectors(rg: np.ndarray, strength: float) -> np.ndarray:
    """UV offsets of RG bytes, as a shader decodes them: ``(rg / 255 * 2 - 1) * strength``.

    Examples
    --------
    >>> rg, s = encode_vectors(np.array([[0.01, -0.02]]), 0.04)
    >>> rg.tolist(), [round(float(v), 3) for v in decode_vectors(rg, s)[0]]
    ([[159, 64]], [0.01, -0.02])
    """
    return (rg.astype(np.float32) / 255.0 * 2.0 - 1.0) * np.float32(strength)


def vector_atlas(uv: np.ndarray, grid: Grid, strength: float | None = None) -> tuple[np.ndarray, float]:
    """``(rows*th, cols*tw, 3)`` RGB image of encoded vectors (B = 0) and the strength."""
    rg, strength = encode_vectors(uv, strength)
    atlas = np.zeros(grid.atlas_shape + (3,), np.uint8)
    atlas[..., :2] = 128
    for k, cell in enumerate(rg):
        atlas[grid.cell(k)][..., :2] = cell
    return atlas, strength


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = c.astype(np.float32) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    s = np.where(c <= 0.0031308, c * 12.92, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.clip(np.rint(s * 255.0), 0, 255).astype(np.uint8)


_LINEAR: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _linear_atlas(color: np.ndarray) -> np.ndarray:
    """:func:`srgb_to_linear` of an atlas, kept for the last atlas asked (blending many frames of one)."""
    hit = _LINEAR.get(id(color))
    if hit is None or hit[0] is not color:
        _LINEAR.clear()
        hit = _LINEAR[id(color)] = (color, srgb_to_linear(color))
    return hit[1]


def _sample(atlas: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear, clamp-to-edge sample of ``atlas`` at UV (v up), as a GPU sampler does."""
    import cv2

    h, w = atlas.shape[:2]
    x = (u * w - 0.5).astype(np.float32)
    y = ((1.0 - v) * h - 0.5).astype(np.float32)
    return cv2.remap(atlas, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def shader_blend(
    color: np.ndarray, vectors: np.ndarray, grid: Grid, strength: float, k: int, blend: float
) -> np.ndarray:
    """Frame ``k + blend`` of a flipbook as the engine shader draws it (linear-light sampling of
    the sRGB atlas, motion-vector blend between frames ``k`` and ``k + 1``, wrapping)."""
    th, tw = grid.tile
    n = grid.frames
    lin = _linear_atlas(color)
    mv = vectors[..., :2].astype(np.float32)
    ju, jv = np.meshgrid((np.arange(tw) + 0.5) / tw, 1.0 - (np.arange(th) + 0.5) / th)  # tile UV, v up

    def atlas_uv(cell: int, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, c = divmod(cell, grid.cols)
        return (c + u) / grid.cols, (grid.rows - 1 - r + v) / grid.rows

    out = np.zeros((th, tw, color.shape[2]), np.float32)
    for cell, sign, weight in ((k % n, -blend, 1.0 - blend), ((k + 1) % n, 1.0 - blend, blend)):
        u, v = atlas_uv(cell, ju, jv)
        d = decode_vectors(_sample(mv, u, v), strength)
        du, dv = d[..., 0] / grid.cols, d[..., 1] / grid.rows  # tile UV -> atlas UV
        out += weight * _sample(lin, u + sign * du, v + sign * dv)
    return linear_to_srgb(out)


def crossfade(color: np.ndarray, grid: Grid, k: int, blend: float) -> np.ndarray:
    """Frame ``k + blend`` as a plain flipbook crossfade (in linear light) draws it."""
    lin = _linear_atlas(color)
    a, b = lin[grid.cell(k % grid.frames)], lin[grid.cell((k + 1) % grid.frames)]
    return linear_to_srgb((1.0 - blend) * a + blend * b)


def sidecar(
    name: str,
    grid: Grid,
    *,
    fps: float,
    loop: str,
    strength: float | None,
    source: dict,
    wrap: dict | None = None,
    layout: str = "atlas",
    packed: dict | None = None,
) -> dict:
    """The ``NAME.json`` description of an exported flipbook, with the engine settings."""
    th, tw = grid.tile
    files = {"color": f"{name}_{grid.cols}x{grid.rows}.png"}
    if layout == "array":
        files = {"color": f"{name}_array_rgba8.raw"}
    doc = {
        "name": name,
        "layout": layout,
        "cols": grid.cols,
        "rows": grid.rows,
        "frames": grid.frames,
        "tile_width": tw,
        "tile_height": th,
        "atlas_width": grid.cols * tw,
        "atlas_height": grid.rows * th,
        "order": "row-major from the top-left; cells past the last frame are black",
        "fps": fps,
        "loop": loop,
        "color_space": "sRGB",
        "source": source,
    }
    if strength is not None:
        files["motion_vectors"] = (
            f"{name}_array_rg8.raw" if layout == "array" else f"{name}_{grid.cols}x{grid.rows}_mv.png"
        )
        doc["motion_vectors"] = {
            "color_space": "linear (import with sRGB off)",
            "encoding": "R = u, G = v (v up), byte = 127.5 + 127.5 * offset / strength; decode rg * 2 - 1",
            "cell_k": "motion at frame k: mean of the flows from frame k-1 to k and k to k+1 (wrapping)",
            "strength_tile_uv": strength,
            "unity_vfx_motion_vector_scale": strength / grid.cols if grid.cols == grid.rows else None,
            "unity_vfx_motion_vector_scale_uv": [strength / grid.cols, strength / grid.rows],
            "unreal_flipbook_motion_vector_strength": strength,
            "flow": "OpenCV Farneback on grey tiles, parameters " + ", ".join(map(str, FLOW_PARAMS)),
        }
    if layout == "array":
        doc["array"] = {
            "layers": grid.frames,
            "color": "RGBA8, one layer after another, rows top to bottom",
            "motion_vectors": "RG8, same order",
        }
    if packed is not None:
        doc["packing"] = packed
    doc["files"] = files
    if wrap is not None:
        doc["wrap_discontinuity"] = wrap
    return doc


__all__ = [
    "FLOW_PARAMS",
    "Grid",
    "choose_grid",
    "color_atlas",
    "crossfade",
    "decode_vectors",
    "encode_vectors",
    "fit",
    "flow_to_uv",
    "frame_motion",
    "optical_flow",
    "packing",
    "shader_blend",
    "sidecar",
    "vector_atlas",
]
