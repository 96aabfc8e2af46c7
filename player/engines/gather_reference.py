"""The gather engine's contract in numpy: packed source maps, wrapping, time units and
smoothing of the time maps, fixed-point tones, and :func:`gather_reference`, the frame every
gather kernel computes the same integers as (:mod:`dynatex.player.engines.gather` draws it).

Examples
--------
>>> import numpy as np
>>> unpack_source(pack_source(np.array([5, 7]), 2))
(array([5, 7]), array([2, 2]))
"""

from __future__ import annotations

import math

import numpy as np

from ...checks import check_float
from ...errors import InvalidArgumentError
from ...tiledb.tiles import MAX_TONES

WRAPS = ("loop", "clamp", "pingpong")
MAX_FRAME_PIXELS = 1 << 24
MAX_GAIN, MAX_OFFSET = 63.0, 255.0  # the fixed-point tone's range (every intermediate fits 16 bits)


# -- numpy references ------------------------------------------------------------------------
def pack_source(index: np.ndarray, tone: np.ndarray | int = 0) -> np.ndarray:
    """Pack source pixel indices (``y * w + x`` inside a stored frame) and tone indices into int32.

    Examples
    --------
    >>> int(pack_source(np.array(5), 2))
    33554437
    """
    index = np.asarray(index, np.int64)
    tone = np.asarray(tone, np.int64)
    if index.size and (index.min() < 0 or index.max() >= MAX_FRAME_PIXELS):
        raise InvalidArgumentError(f"source index must be in [0, {MAX_FRAME_PIXELS})")
    if tone.size and (tone.min() < 0 or tone.max() >= MAX_TONES):
        raise InvalidArgumentError(f"tone must be in [0, {MAX_TONES})")
    return ((tone << 24) | index).astype(np.uint32).view(np.int32)


def unpack_source(packed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(index, tone)`` of packed source entries."""
    u = np.asarray(packed).astype(np.int32).view(np.uint32)
    return (u & 0xFFFFFF).astype(np.int64), (u >> 24).astype(np.int64)


def wrap_index(i: np.ndarray, n: int, wrap: str) -> np.ndarray:
    """Frame index ``i`` (integers, any range) folded into ``[0, n)`` by ``wrap``."""
    i = np.asarray(i, np.int64)
    if wrap == "loop":
        return np.mod(i, n)
    if wrap == "clamp":
        return np.clip(i, 0, n - 1)
    if wrap == "pingpong":
        if n == 1:
            return np.zeros_like(i)
        period = 2 * (n - 1)
        m = np.mod(i, period)
        return np.where(m < n, m, period - m)
    raise InvalidArgumentError(f"wrap must be one of {WRAPS}, not {wrap!r}")


def gaussian_weights(sigma: float) -> np.ndarray:
    """Normalised float32 taps of a Gaussian truncated at ``ceil(3 sigma)`` (one tap when sigma is 0)."""
    sigma = check_float("sigma", sigma, 0.0, 1e4)
    radius = int(math.ceil(3.0 * sigma))
    if radius == 0:
        return np.ones(1, np.float32)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return (w / w.sum()).astype(np.float32)


def gaussian_smooth(field: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian smoothing of a 2-D float map with clamped edges (reference of kernel ``smooth``).

    Examples
    --------
    >>> m = np.zeros((5, 9), np.float32); m[:, 4:] = 10
    >>> s = gaussian_smooth(m, 1.0)
    >>> bool(0 < s[0, 4] < 10 and abs(float(s[0, 0])) < 1e-6)
    True
    """
    field = np.asarray(field, np.float32)
    if field.ndim != 2:
        raise InvalidArgumentError(f"field must be 2-D, not shape {field.shape}")
    w = gaussian_weights(sigma)
    r = (len(w) - 1) // 2
    if r == 0:
        return field.copy()
    out = field
    for axis in (1, 0):
        n = out.shape[axis]
        acc = np.zeros_like(out)
        for k in range(-r, r + 1):
            idx = np.clip(np.arange(n) + k, 0, n - 1)
            acc += w[k + r] * np.take(out, idx, axis=axis)
        out = acc
    return out


def time_units(
    tmap: np.ndarray,
    t: float,
    shape: tuple[int, int],
    step: int,
    *,
    target: np.ndarray | None = None,
    fade: float = 0.0,
    rows: range | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ``(frame, weight)`` int64 ``(H, W)`` (only the output rows ``rows`` when
    given): the frame ``floor(time)`` and the weight of the next frame in 255ths, for time
    ``t`` plus the time map ``tmap`` at lattice ``step`` (faded toward ``target`` by
    ``fade``), computed in integers after one float32 rounding per map sample (module
    docstring; the kernels compute the same integers).

    Examples
    --------
    >>> f, w = time_units(np.zeros((1, 1), np.float32), 2.5, (1, 1), 1)
    >>> int(f[0, 0]), int(w[0, 0])          # halfway to frame 3: 128/255 (rounded up)
    (2, 128)
    """
    m = np.asarray(tmap, np.float32)
    if target is not None:
        m = m + np.float32(fade) * (np.asarray(target, np.float32) - m)
    t = np.float32(t)
    base = np.floor(t)
    q = np.floor((t - base + m) * np.float32(4080) + np.float32(0.5)).astype(np.int64)
    h, w = shape
    rows = range(h) if rows is None else rows
    if step == 1:
        u = (q[rows.start : rows.stop] + 8) // 16
    else:
        th, tw = q.shape
        ny = 2 * np.arange(rows.start, rows.stop) + 1 - step
        yi = ny // (2 * step)
        ky = (ny - 2 * step * yi)[:, None]
        nx = 2 * np.arange(w) + 1 - step
        xi = nx // (2 * step)
        kx = (nx - 2 * step * xi)[None, :]
        c0, c1 = np.clip(xi, 0, tw - 1), np.clip(xi + 1, 0, tw - 1)
        h_rows = [
            (q[r][:, c0] * (2 * step - kx) + q[r][:, c1] * kx + 16 * step) // (32 * step)
            for r in (np.clip(yi, 0, th - 1), np.clip(yi + 1, 0, th - 1))
        ]
        u = (h_rows[0] * (2 * step - ky) + h_rows[1] * ky + step) // (2 * step)
    frame = u // 255
    return int(base) + frame, u - 255 * frame


def source_indices(
    source: np.ndarray, shape: tuple[int, int], frame_w: int, cell: tuple[int, int] | None, rows: range | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ``(pixel index, tone)`` of a per-pixel map (``cell=None``) or a cell grid
    (only the output rows ``rows`` when given)."""
    h, w = shape
    rows = range(h) if rows is None else rows
    if cell is None:
        return unpack_source(source[rows.start : rows.stop])
    idx, tone = unpack_source(source)
    ch, cw = cell
    yy, xx = np.arange(rows.start, rows.stop), np.arange(w)
    cy, cx = yy // ch, xx // cw
    pix = idx[cy][:, cx] + ((yy - cy * ch) * frame_w)[:, None] + (xx - cx * cw)[None, :]
    return pix, tone[cy][:, cx]


def fixed_tones(tones: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fixed-point tone ``(G, O)`` int32 ``(n, 3)`` of a float table ``(n, 6)`` (gain rgb,
    offset rgb): ``G = round(gain 2**17 / 255)``, ``O = round(2 (128 gain + offset)) + 1``
    (module docstring)."""
    tones = np.asarray(tones, np.float64)
    gain = np.clip(tones[:, :3], 0, MAX_GAIN)
    offset = np.clip(tones[:, 3:], -MAX_OFFSET, MAX_OFFSET)
    g = np.rint(gain * (2**17 / 255))
    o = np.rint(2 * (128 * gain + offset)) + 1
    return g.astype(np.int32), o.astype(np.int32)


def gather_reference(
    stack: np.ndarray,
    pix: np.ndarray,
    tone: np.ndarray,
    frames: np.ndarray,
    weights: np.ndarray,
    tones: np.ndarray,
    *,
    wrap: str = "loop",
    interpolate: bool = True,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Reference of kernel ``gather``: ``stack`` (N, h, w, 3) uint8, per-pixel ``pix``/``tone``
    (H, W) ints, per-pixel ``frames`` (any integers, folded by ``wrap``) and ``weights`` of
    the next frame in 255ths (:func:`time_units`), ``tones`` (n, 6) float32 (gain rgb,
    offset rgb).

    The fixed-point formula of the module docstring, evaluated exactly.
    """
    n = stack.shape[0]
    flat = stack.reshape(n, -1, 3)
    frames = np.asarray(frames, np.int64)
    a = flat[wrap_index(frames, n, wrap), pix].astype(np.int32) - 128
    if interpolate:
        w = np.clip(np.asarray(weights, np.int32), 0, 255)[..., None]
        b = flat[wrap_index(frames + 1, n, wrap), pix].astype(np.int32) - 128
        v = (255 - w) * a + w * b
    else:
        v = 255 * a
    gain, offset = fixed_tones(tones)
    res = np.clip((((v * gain[tone]) >> 16) + offset[tone]) >> 1, 0, 255).astype(np.uint8)
    if out is None:
        return res
    out[...] = res
    return out


# -- the device-backed gather ------------------------------------------------------------------
