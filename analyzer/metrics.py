"""Objective quality measures for synthesized dynamic textures.

Every function takes clips as arrays ``(T, H, W)`` or ``(T, H, W, C)`` (uint8, or floats on
the 0..255 scale; ``C`` is 1 or 3) and keyword-only options. See ``analyzer/METRICS.md``
for the definition, units, range and good/bad values of each measure.

- Long-run stability: :func:`stability` (energy ratio per time window, NaN/inf count).
- Seam visibility: :func:`seam_visibility` with :func:`grid_labels`.
- Temporal discontinuity: :func:`temporal_discontinuity`, :func:`frame_step_ratio`.
- Likeness to the source: :func:`spectrum_distance` (:func:`st_power_spectrum`),
  :func:`patch_coherence`, :func:`patch_completeness` (both at once: :func:`patch_distances`).
- Double images (a crossfade showing two objects): :func:`double_image`,
  :func:`double_image_level` (the source's own level), :func:`crossfade_double_image`.
- Coverage and repetition: :func:`frame_coverage`, :func:`index_coverage`,
  :func:`repetition_lag` (:func:`repetition_profile`).
- Repetition in space: :func:`lattice_prominence` (a cell lattice standing out),
  :func:`lattice_correlation`.
- Colours the source never had: :func:`out_of_gamut_share`, calibrated by :func:`source_gamut_share`.
- All of them at once: :func:`evaluate`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import Range, check_frames, check_int
from ..errors import ArgumentTypeError, InvalidArgumentError

__all__ = [
    "DoubleImages",
    "StabilityReport",
    "check_frames",
    "colour_set",
    "count_nonfinite",
    "crossfade_double_image",
    "double_image",
    "double_image_level",
    "evaluate",
    "frame_coverage",
    "frame_step_ratio",
    "grid_labels",
    "index_coverage",
    "lattice_correlation",
    "lattice_lags",
    "lattice_prominence",
    "out_of_gamut_share",
    "patch_coherence",
    "patch_completeness",
    "patch_distances",
    "repetition_lag",
    "repetition_profile",
    "seam_visibility",
    "source_gamut_share",
    "spectrum_distance",
    "st_power_spectrum",
    "stability",
    "temporal_discontinuity",
]

_LUMA = np.array([0.299, 0.587, 0.114], np.float32)
_CHUNK = 32  # frames converted to float at a time (bounds memory on long clips)
_THUMB = 32  # longer side of the thumbnails used by coverage and repetition
_GHOST_SIDE = 96  # longer side of the luma frames the double-image measure compares
_GHOST_MOVING = 0.75  # the moving region: pixels whose temporal deviation is above this quantile


#: a positive finite number (eps, floors, tolerances)
_POSITIVE = Range(float, 0.0, None, low_open=True)


def _pair(name: str, value: Any, lo: int) -> tuple[int, int]:
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (value, value)
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{name} must be an integer or a pair of integers, not {value!r}") from None
    return check_int(f"{name}[0]", a, lo), check_int(f"{name}[1]", b, lo)


def _same_size(a: np.ndarray, b: np.ndarray, what: str) -> None:
    if a.shape[1:3] != b.shape[1:3]:
        raise InvalidArgumentError(
            f"{what} needs output and source of the same frame size; output is "
            f"{a.shape[2]}x{a.shape[1]}, source {b.shape[2]}x{b.shape[1]}"
        )


def count_nonfinite(frames: Any) -> int:
    """Number of frames that hold at least one NaN or inf value.

    Examples
    --------
    >>> f = np.zeros((3, 2, 2), np.float32); f[1, 0, 0] = np.nan
    >>> count_nonfinite(f)
    1
    """
    arr = np.asarray(frames)
    if arr.dtype.kind != "f" or arr.size == 0:
        return 0
    bad = 0
    for i in range(0, arr.shape[0], _CHUNK):
        c = arr[i : i + _CHUNK]
        bad += int((~np.isfinite(c.reshape(c.shape[0], -1))).any(axis=1).sum())
    return bad


# -- helpers: float chunks, grey, downscaling ------------------------------------------------
def _chunks(frames: np.ndarray, start: int = 0, stop: int | None = None):
    stop = frames.shape[0] if stop is None else stop
    for i in range(start, stop, _CHUNK):
        yield i, frames[i : min(i + _CHUNK, stop)].astype(np.float32)


def _grey(frames: np.ndarray, factor: int = 1, size: tuple[int, int] | None = None) -> np.ndarray:
    """``(T, H', W')`` float32 luma, area-downscaled by ``factor`` (or to ``size`` = (H', W'))."""
    import cv2

    t, h, w, c = frames.shape
    if size is None:
        size = (max(1, h // factor), max(1, w // factor))
    out = np.empty((t,) + tuple(size), np.float32)
    for i, chunk in _chunks(frames):
        g = chunk[..., 0] if c == 1 else chunk @ _LUMA
        if size == (h, w):
            out[i : i + len(g)] = g
        else:
            for k in range(len(g)):
                out[i + k] = cv2.resize(g[k], (size[1], size[0]), interpolation=cv2.INTER_AREA)  # cv2: (w, h)
    return out


def _auto_downscale(source: np.ndarray, downscale: int | None) -> int:
    if downscale is None:
        return max(1, min(source.shape[1], source.shape[2]) // 128)
    return check_int("downscale", downscale, 1)


def _thumb_size(shape: tuple[int, ...]) -> tuple[int, int]:
    h, w = shape[1], shape[2]
    s = min(1.0, _THUMB / max(h, w))
    return max(1, round(h * s)), max(1, round(w * s))


def _step_rms(frames: np.ndarray) -> np.ndarray:
    """RMS difference (grey levels, over pixels and channels) between consecutive frames, ``(T-1,)``."""
    t = frames.shape[0]
    out = np.empty(max(t - 1, 0), np.float64)
    prev = None
    for i, chunk in _chunks(frames):
        if prev is not None:
            chunk = np.concatenate([prev, chunk])
            first = i - 1
        else:
            first = i
        d = np.diff(chunk, axis=0).reshape(chunk.shape[0] - 1, -1)
        out[first : first + len(d)] = np.sqrt(np.einsum("ij,ij->i", d, d, dtype=np.float64) / d.shape[1])
        prev = chunk[-1:]
    return out


def _median_step(frames: np.ndarray, name: str) -> float:
    steps = _step_rms(frames)
    ref = float(np.median(steps))
    if ref <= 0:
        raise InvalidArgumentError(f"{name} does not change from frame to frame (median frame difference is 0)")
    return ref


# -- long-run stability -----------------------------------------------------------------
@dataclass(frozen=True)
class StabilityReport:
    """Result of :func:`stability`.

    ``ratios[k]`` is the mean dynamic energy of output window ``k`` over that of the source
    (NaN for a window whose frames are all non-finite). ``source_min_ratio`` and
    ``source_max_ratio`` are the same ratios of the source's own windows: how much a real
    clip's energy varies from window to window (boiling water: 0.55..2.12 in windows of 25).
    """

    ratios: np.ndarray
    window: int
    n_frames: int
    nonfinite_frames: int
    source_min_ratio: float = 1.0
    source_max_ratio: float = 1.0

    @property
    def min_ratio(self) -> float:
        r = self.ratios[np.isfinite(self.ratios)]
        return float(r.min()) if r.size else float("nan")

    @property
    def max_ratio(self) -> float:
        r = self.ratios[np.isfinite(self.ratios)]
        return float(r.max()) if r.size else float("nan")

    @property
    def final_ratio(self) -> float:
        return float(self.ratios[-1])

    def bounds(self, *, low: float = 0.5, high: float = 2.0) -> tuple[float, float]:
        """The band every window must lie in: ``[low, high]``, widened to the source's own
        window-to-window range with a margin (``0.8 source_min_ratio``, ``1.25 source_max_ratio``),
        so a clip whose energy varies over time is stable against itself."""
        return min(low, 0.8 * self.source_min_ratio), max(high, 1.25 * self.source_max_ratio)

    def is_stable(self, *, low: float = 0.5, high: float = 2.0) -> bool:
        """True when every frame is finite and every window's ratio lies in :meth:`bounds`."""
        lo, hi = self.bounds(low=low, high=high)
        return bool(
            self.nonfinite_frames == 0
            and np.isfinite(self.ratios).all()
            and self.ratios.min() >= lo
            and self.ratios.max() <= hi
        )

    def as_dict(self) -> dict[str, Any]:
        lo, hi = self.bounds()
        return {
            "window": self.window,
            "n_frames": self.n_frames,
            "nonfinite_frames": self.nonfinite_frames,
            "min_ratio": _json_float(self.min_ratio),
            "max_ratio": _json_float(self.max_ratio),
            "final_ratio": _json_float(self.final_ratio),
            "stable": self.is_stable(),
            "source_min_ratio": _json_float(self.source_min_ratio),
            "source_max_ratio": _json_float(self.source_max_ratio),
            "bounds": [_json_float(lo), _json_float(hi)],
            "ratios": [_json_float(v) for v in self.ratios],
        }


def stability(output: np.ndarray | Iterable[np.ndarray], source: np.ndarray, *, window: int = 25) -> StabilityReport:
    """Long-run stability: output energy over source energy, per window of ``window`` frames.

    The dynamic energy of a frame is its mean squared deviation (over pixels and channels)
    from the source's mean frame. A model that decays to its mean image drives the ratio
    towards 0; one that blows up drives it far above 1; NaN/inf frames are counted.

    Parameters
    ----------
    output : ndarray or iterable of frames
        ``(T, H, W[, C])``, or any iterable of ``(H, W[, C])`` frames (a long run is
        consumed one frame at a time, never held in memory). Floats may hold NaN/inf.
    source : ndarray
        ``(T, H, W[, C])`` source clip, same frame size and channels as ``output``.
    window : int
        Frames per window (the last window may be shorter).

    Returns
    -------
    StabilityReport

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> src = rng.integers(0, 256, (20, 8, 8, 3)).astype(np.uint8)
    >>> rep = stability(src, src, window=20)
    >>> np.round(rep.ratios, 6).tolist(), rep.nonfinite_frames, rep.is_stable()
    ([1.0], 0, True)
    """
    window = check_int("window", window, 1)
    source = check_frames(source, name="source", min_frames=2)
    mean = np.zeros(source.shape[1:], np.float64)
    for _, chunk in _chunks(source):
        mean += chunk.sum(axis=0, dtype=np.float64)
    mean = (mean / source.shape[0]).astype(np.float32)
    src_energies = _energies(source, mean)
    src_e = float(np.mean(src_energies))
    if src_e <= 0:
        raise InvalidArgumentError("source has no temporal variation (every frame equals the mean frame)")

    if isinstance(output, np.ndarray):
        output = check_frames(output, name="output", allow_nonfinite=True)
        if output.shape[1:] != source.shape[1:]:
            raise InvalidArgumentError(
                f"stability needs output frames shaped like the source's {source.shape[1:]}, not {output.shape[1:]}"
            )
        energies = _energies(output, mean)
    else:
        energies = _energies_iter(output, mean)
    n = energies.size
    if n == 0:
        raise InvalidArgumentError("output is empty (no frames)")
    bad = ~np.isfinite(energies)
    ratios = []
    for i in range(0, n, window):
        e, b = energies[i : i + window], bad[i : i + window]
        ratios.append(float(e[~b].mean()) / src_e if (~b).any() else float("nan"))
    own = [float(src_energies[i : i + window].mean()) / src_e for i in range(0, len(src_energies), window)]
    return StabilityReport(
        ratios=np.asarray(ratios),
        window=window,
        n_frames=n,
        nonfinite_frames=int(bad.sum()),
        source_min_ratio=min(own),
        source_max_ratio=max(own),
    )


def _energies(frames: np.ndarray, mean: np.ndarray) -> np.ndarray:
    out = np.empty(frames.shape[0], np.float64)
    for i, chunk in _chunks(frames):
        d = (chunk - mean).reshape(chunk.shape[0], -1)
        with np.errstate(invalid="ignore", over="ignore"):
            e = np.einsum("ij,ij->i", d, d, dtype=np.float64) / d.shape[1]
        out[i : i + len(e)] = np.where(np.isfinite(e), e, np.nan)
    return out


def _energies_iter(frames: Iterable[np.ndarray], mean: np.ndarray) -> np.ndarray:
    out: list[float] = []
    for k, f in enumerate(frames):
        a = np.asarray(f)
        if a.ndim == 2:
            a = a[..., None]
        if a.shape != mean.shape:
            raise InvalidArgumentError(f"output frame {k} has shape {a.shape}, not the source's {mean.shape}")
        if a.dtype.kind not in "uif":
            raise ArgumentTypeError(f"output frame {k} must hold numbers, not {a.dtype}")
        out.append(float(_energies(a[None], mean)[0]))
    return np.asarray(out, np.float64)


# -- seam visibility ----------------------------------------------------------------------
def grid_labels(shape: Sequence[int], tile: int | Sequence[int], *, offset: Sequence[int] = (0, 0)) -> np.ndarray:
    """Label map of a tile grid: pixel ``(y, x)`` gets the index of its tile.

    Parameters
    ----------
    shape : (H, W)
        Frame size.
    tile : int or (th, tw)
        Tile height and width in pixels.
    offset : (oy, ox)
        Grid shift: tile boundaries sit where ``(y + oy) % th == 0`` (and likewise for x).

    Examples
    --------
    >>> grid_labels((4, 6), (2, 3))
    array([[0, 0, 0, 1, 1, 1],
           [0, 0, 0, 1, 1, 1],
           [2, 2, 2, 3, 3, 3],
           [2, 2, 2, 3, 3, 3]], dtype=int32)
    """
    h, w = _pair("shape", tuple(shape), 1)
    th, tw = _pair("tile", tile, 1)
    oy, ox = _pair("offset", tuple(offset), 0)
    ry = (np.arange(h) + oy) // th
    rx = (np.arange(w) + ox) // tw
    ry -= ry[0]
    rx -= rx[0]
    return (ry[:, None] * (rx[-1] + 1) + rx[None, :]).astype(np.int32)


def seam_visibility(
    frames: np.ndarray, labels: np.ndarray | None = None, *, wrap: bool = False, eps: float = 1e-3
) -> np.ndarray:
    """Gradient energy across boundaries over gradient energy in the interior, per frame.

    Every pair of 4-neighbour pixels is an *edge*. An edge whose two pixels carry different
    ``labels`` is a boundary edge (a tile, block or quilt-cut seam); with ``wrap=True`` the
    frame is a torus and the edges from the last column to the first and from the last row
    to the first (the border of a tileable texture) are boundary edges too. For each frame,
    the summed squared RGB difference across boundary edges is divided by what those edges
    would hold if they looked like the interior: their count times the mean squared
    difference of interior edges of the same direction (horizontal or vertical), so that
    anisotropic textures do not bias the ratio. 1 means the seams look like the texture;
    above 1 they show.

    Parameters
    ----------
    frames : ndarray
        ``(T, H, W[, C])`` output clip.
    labels : ndarray, optional
        ``(H, W)`` integer (or boolean) region map: tile index, quilt block index, mask.
        ``None`` with ``wrap=True`` measures only the wrap-around border.
    wrap : bool
        Also count the wrap-around border as a boundary.
    eps : float
        Added to both energies (grey levels squared), so flat frames give 1, not 0/0.

    Returns
    -------
    ndarray
        ``(T,)`` ratios; ``.mean()`` is the clip's seam visibility.

    Examples
    --------
    >>> f = np.zeros((2, 4, 4), np.uint8); f[:, :, 2:] = 50    # a step at column 2
    >>> seam_visibility(f, grid_labels((4, 4), (4, 2))).round(0).tolist()
    [2500001.0, 2500001.0]
    """
    frames = check_frames(frames, name="frames")
    eps = _POSITIVE.check("eps", eps)
    t, h, w, c = frames.shape
    if labels is None:
        if not wrap:
            raise InvalidArgumentError("labels is None and wrap is False: there is no boundary to measure")
        labels = np.zeros((h, w), np.int32)
    labels = np.asarray(labels)
    if labels.ndim != 2 or labels.dtype.kind not in "uib":
        raise ArgumentTypeError(f"labels must be a 2-D integer or boolean map, not {labels.dtype} {labels.shape}")
    if labels.shape != (h, w):
        raise InvalidArgumentError(f"labels map is {labels.shape[1]}x{labels.shape[0]} but frames are {w}x{h}")
    if wrap:
        bh = labels != np.roll(labels, -1, axis=1)
        bh[:, -1] = True
        bv = labels != np.roll(labels, -1, axis=0)
        bv[-1, :] = True
    else:
        bh = labels[:, 1:] != labels[:, :-1]
        bv = labels[1:, :] != labels[:-1, :]
    nbh, nbv = int(bh.sum()), int(bv.sum())
    nih, niv = bh.size - nbh, bv.size - nbv
    nb = nbh + nbv
    if nb == 0:
        raise InvalidArgumentError("boundaries: no boundary lies inside the frame (a single region covers it)")
    if nih + niv == 0:
        raise InvalidArgumentError("boundaries: every pixel edge is a boundary; there is no interior to compare with")
    mh, mv = bh.ravel().astype(np.float32), bv.ravel().astype(np.float32)
    out = np.empty(t, np.float64)
    for i, f in _chunks(frames):
        n = f.shape[0]
        if wrap:
            dh = np.roll(f, -1, axis=2) - f
            dv = np.roll(f, -1, axis=1) - f
        else:
            dh = f[:, :, 1:] - f[:, :, :-1]
            dv = f[:, 1:] - f[:, :-1]
        eh = np.einsum("...c,...c->...", dh, dh).reshape(n, -1)
        ev = np.einsum("...c,...c->...", dv, dv).reshape(n, -1)
        b_h, b_v = (eh @ mh).astype(np.float64), (ev @ mv).astype(np.float64)
        i_h = eh.sum(axis=1, dtype=np.float64) - b_h
        i_v = ev.sum(axis=1, dtype=np.float64) - b_v
        pooled = (i_h + i_v) / (nih + niv)
        mean_h = i_h / nih if nih else pooled
        mean_v = i_v / niv if niv else pooled
        # what the boundary edges would hold if they looked like interior edges of the same direction
        expected = nbh * mean_h + nbv * mean_v
        out[i : i + n] = (b_h + b_v + eps * nb) / (expected + eps * nb)
    return out


# -- temporal discontinuity ---------------------------------------------------------------
def temporal_discontinuity(
    output: np.ndarray, events: Sequence[int], *, source: np.ndarray | None = None
) -> np.ndarray:
    """Frame difference at events (loop wrap, reversal, jump) over the source's median frame difference.

    For each event ``e`` (the index of the first frame after the jump), the RMS difference
    (grey levels, over pixels and channels) between output frames ``e - 1`` and ``e`` is
    divided by the median RMS difference between consecutive source frames (of the output
    itself when ``source`` is None). About 1: the jump looks like an ordinary frame step.

    Parameters
    ----------
    output : ndarray
        ``(T, H, W[, C])`` output clip.
    events : sequence of int
        Frame indices in ``1 .. T-1``.
    source : ndarray, optional
        ``(T', H', W'[, C])`` source clip giving the reference frame step (any size).

    Returns
    -------
    ndarray
        ``(len(events),)`` ratios.

    Examples
    --------
    >>> ramp = np.repeat(np.arange(0, 40, 2, dtype=np.uint8), 4).reshape(20, 2, 2)
    >>> loop = np.concatenate([ramp[:10], ramp[:10]])
    >>> temporal_discontinuity(loop, [10], source=ramp).tolist()
    [9.0]
    """
    output = check_frames(output, name="output", min_frames=2)
    ev = _events(events, output.shape[0])
    ref = _median_step(
        output if source is None else check_frames(source, name="source", min_frames=2),
        "output" if source is None else "source",
    )
    out = np.empty(len(ev), np.float64)
    for k, e in enumerate(ev):
        d = output[e].astype(np.float64) - output[e - 1].astype(np.float64)
        out[k] = math.sqrt(float(np.mean(d * d))) / ref
    return out


def _events(events: Any, t: int) -> list[int]:
    if isinstance(events, (int, np.integer)) and not isinstance(events, bool):
        events = [events]
    try:
        ev = list(events)
    except TypeError:
        raise ArgumentTypeError(f"events must be a sequence of frame indices, not {events!r}") from None
    out = []
    for e in ev:
        if isinstance(e, bool) or not isinstance(e, (int, np.integer)):
            raise ArgumentTypeError(f"events must be integers, not {e!r}")
        if not 1 <= e <= t - 1:
            raise InvalidArgumentError(
                f"event {int(e)} is outside the output's frames 1..{t - 1} "
                "(an event is the index of the first frame after a jump)"
            )
        out.append(int(e))
    return out


def frame_step_ratio(output: np.ndarray, source: np.ndarray) -> float:
    """Median consecutive-frame difference of the output over that of the source.

    About 1 when the output moves like the source; far above 1 when it jumps every frame
    (frames shuffled in time); near 0 when it freezes.

    Examples
    --------
    >>> ramp = np.repeat(np.arange(0, 40, 2, dtype=np.uint8), 4).reshape(20, 2, 2)
    >>> frame_step_ratio(ramp[::2], ramp)
    2.0
    """
    output = check_frames(output, name="output", min_frames=2)
    source = check_frames(source, name="source", min_frames=2)
    return float(np.median(_step_rms(output))) / _median_step(source, "source")


# -- double images ------------------------------------------------------------------------------
class DoubleImages:
    """The double-image measure against one source, its thumbnails computed once (see
    :func:`double_image`): ``of(frames)``, ``crossfades(first, second, weight)``, ``level()``."""

    def __init__(self, source: np.ndarray) -> None:
        source = check_frames(source, name="source", min_frames=2)
        self.shape = source.shape[1:3]
        h, w = self.shape
        s = min(1.0, _GHOST_SIDE / max(h, w))
        self.size = max(1, round(h * s)), max(1, round(w * s))
        g = _grey(source, size=self.size)
        dev = g.std(axis=0)
        self.moving = dev >= np.quantile(dev, _GHOST_MOVING)
        #: the source's thumbnails over the moving region, ``(T, M)``
        self.rows = g[:, self.moving].astype(np.float64)
        self._norms = np.einsum("ij,ij->i", self.rows, self.rows)
        self.step = float(np.median(np.sqrt(np.mean(np.diff(self.rows, axis=0) ** 2, axis=1))))
        if self.step <= 0:
            raise InvalidArgumentError("source does not change from frame to frame (median frame difference is 0)")

    def of(self, frames: np.ndarray) -> np.ndarray:
        """The measure of each frame of ``frames`` (the source's frame size)."""
        frames = check_frames(frames, name="output")
        if frames.shape[1:3] != self.shape:
            raise InvalidArgumentError(
                f"double_image needs output and source of one frame size: {frames.shape[1:3]} vs {self.shape}"
            )
        return self._ratios(_grey(frames, size=self.size)[:, self.moving].astype(np.float64))

    def crossfades(self, first: Any, second: Any, weight: Any) -> np.ndarray:
        """The measure of ``(1 - weight) * source[first] + weight * source[second]`` (arrays of one shape)."""
        a, b = np.asarray(first), np.asarray(second)
        w = np.asarray(weight, np.float64)
        if a.shape != b.shape or a.shape != w.shape:
            raise InvalidArgumentError(
                f"first, second and weight must have one shape, not {a.shape}, {b.shape}, {w.shape}"
            )
        t = len(self.rows)
        for name, idx in (("first", a), ("second", b)):
            if idx.size and (idx.dtype.kind not in "ui" or idx.min() < 0 or idx.max() >= t):
                raise InvalidArgumentError(f"{name} must be frame indices in 0..{t - 1}")
        if a.size and (not np.isfinite(w).all() or w.min() < 0 or w.max() > 1):
            raise InvalidArgumentError("weight must lie in [0, 1]")
        a, b, w = a.ravel(), b.ravel(), w.ravel()[:, None]
        return self._ratios((1 - w) * self.rows[a] + w * self.rows[b]).reshape(np.shape(first))

    def level(self, quantile: float = 0.9) -> float:
        """The ``quantile`` of the measure over the means of consecutive source frames."""
        q = Range(float, 0.0, 1.0).check("quantile", quantile)
        return float(np.quantile(self._ratios((self.rows[:-1] + self.rows[1:]) / 2), q))

    def _ratios(self, q: np.ndarray) -> np.ndarray:
        """RMS distance of each row of ``q`` to its nearest source row, over the median step."""
        out = np.empty(len(q))
        for i in range(0, len(q), 256):
            c = q[i : i + 256]
            d2 = np.einsum("ij,ij->i", c, c)[:, None] + self._norms[None, :] - 2.0 * (c @ self.rows.T)
            out[i : i + len(c)] = np.sqrt(np.maximum(d2.min(axis=1), 0.0) / self.rows.shape[1])
        return out / self.step


def double_image(output: np.ndarray, source: np.ndarray) -> np.ndarray:
    """Per output frame: how far it is from the nearest source frame, in the source's moving
    region, over the source's median frame step there.

    0 for a frame the source holds; about 0.5 for the mean of two consecutive source frames
    (the in-between a fractional speed shows, see :func:`double_image_level`); about 1 or more
    for a crossfade of two frames whose moving parts sit in different places (two
    half-transparent objects). Luma thumbnails (longer side 96 pixels); the moving region is
    the quarter of the pixels with the largest temporal standard deviation in the source.
    :class:`DoubleImages` keeps one source's thumbnails for many calls.

    Examples
    --------
    >>> clip = np.zeros((16, 8, 32), np.uint8)
    >>> for i in range(16):
    ...     clip[i, :, 4 + i : 12 + i] = 200              # a bar 8 pixels wide moving 1 pixel a frame
    >>> ghost = (clip[2].astype(float) + clip[10]) / 2    # frames 8 apart, crossfaded
    >>> round(float(double_image(ghost[None], clip)[0]), 2), double_image(clip[:3], clip).tolist()
    (1.5, [0.0, 0.0, 0.0])
    """
    return DoubleImages(source).of(output)


def double_image_level(source: np.ndarray, *, quantile: float = 0.9) -> float:
    """The source's own double-image level: the ``quantile`` of :func:`double_image` over the
    means of consecutive source frames (what playing the source between two frames shows).

    Examples
    --------
    >>> clip = np.zeros((16, 8, 32), np.uint8)
    >>> for i in range(16):
    ...     clip[i, :, 4 + i : 12 + i] = 200
    >>> round(double_image_level(clip), 2)
    0.5
    """
    return DoubleImages(source).level(quantile)


def crossfade_double_image(source: np.ndarray, first: Any, second: Any, weight: Any) -> np.ndarray:
    """:func:`double_image` of the crossfades ``(1 - weight) * source[first] + weight * source[second]``
    (index and weight arrays of one shape), computed on the thumbnails without forming the frames.

    Examples
    --------
    >>> clip = np.zeros((16, 8, 32), np.uint8)
    >>> for i in range(16):
    ...     clip[i, :, 4 + i : 12 + i] = 200
    >>> crossfade_double_image(clip, [3, 2], [4, 10], [0.5, 0.5]).round(2).tolist()
    [0.5, 1.5]
    """
    return DoubleImages(source).crossfades(first, second, weight)


# -- likeness: spatio-temporal power spectrum ------------------------------------------------
def st_power_spectrum(frames: np.ndarray, *, cuboid: Sequence[int] = (16, 32), downscale: int = 1) -> np.ndarray:
    """Binned spatio-temporal power spectrum (Welch estimate) of a clip's luma.

    The luma, area-downscaled by ``downscale``, is cut into cuboids of ``cuboid[0]`` frames
    by ``cuboid[1]`` x ``cuboid[1]`` pixels, overlapping by half in every axis. Each cuboid
    loses its mean, is multiplied by a 3-D Hann window and Fourier transformed; power is
    averaged over cuboids and then over the coefficients of each bin: temporal frequency
    ``|f_t| * cuboid[0]`` (rows, 0 .. cuboid[0]/2) by radial spatial frequency
    ``round(|f_xy| * cuboid[1])`` (columns, 0 .. cuboid[1]/2; corners beyond are dropped).

    Returns
    -------
    ndarray
        ``(cuboid[0] // 2 + 1, cuboid[1] // 2 + 1)`` mean power per coefficient (grey levels^2).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> st_power_spectrum(rng.normal(128, 20, (16, 32, 32)).clip(0, 255), cuboid=(8, 16)).shape
    (5, 9)
    """
    frames = check_frames(frames, name="frames")
    ct, cs = _pair("cuboid", cuboid, 2)
    downscale = check_int("downscale", downscale, 1)
    grey = _grey(frames, downscale)
    return _spectrum(grey, ct, cs)


def _spectrum(grey: np.ndarray, ct: int, cs: int) -> np.ndarray:
    from numpy.lib.stride_tricks import sliding_window_view

    t, h, w = grey.shape
    if t < ct or h < cs or w < cs:
        raise InvalidArgumentError(
            f"clip ({t} frames of {w}x{h} after downscaling) is smaller than the "
            f"spectrum cuboid ({ct} frames of {cs}x{cs})"
        )
    win = (
        np.hanning(ct + 2)[1:-1, None, None]
        * np.hanning(cs + 2)[1:-1][None, :, None]
        * np.hanning(cs + 2)[1:-1][None, None, :]
    ).astype(np.float32)
    st, ss = max(1, ct // 2), max(1, cs // 2)
    acc = np.zeros((ct, cs, cs // 2 + 1), np.float64)
    count = 0
    for t0 in range(0, t - ct + 1, st):
        block = grey[t0 : t0 + ct]
        cub = sliding_window_view(block, (cs, cs), axis=(1, 2))[:, ::ss, ::ss]  # (ct, ny, nx, cs, cs)
        cub = np.moveaxis(cub, 0, 2).reshape(-1, ct, cs, cs)
        cub = cub - cub.mean(axis=(1, 2, 3), keepdims=True)
        spec = np.fft.rfftn(cub * win, axes=(1, 2, 3))
        acc += (spec.real**2 + spec.imag**2).sum(axis=0)
        count += cub.shape[0]
    acc /= count
    ft = np.rint(np.abs(np.fft.fftfreq(ct)) * ct).astype(int)
    fy = np.fft.fftfreq(cs)
    fx = np.fft.rfftfreq(cs)
    fr = np.rint(np.sqrt(fy[:, None] ** 2 + fx[None, :] ** 2) * cs).astype(int)
    nt, nr = ct // 2 + 1, cs // 2 + 1
    keep = np.broadcast_to(fr <= nr - 1, acc.shape)
    idx = ft[:, None, None] * nr + fr[None, :, :]
    idx = np.broadcast_to(idx, acc.shape)[keep]
    sums = np.bincount(idx, weights=acc[keep], minlength=nt * nr)
    cnts = np.bincount(idx, minlength=nt * nr)
    return (sums / np.maximum(cnts, 1)).reshape(nt, nr)


def spectrum_distance(
    output: np.ndarray,
    source: np.ndarray,
    *,
    cuboid: Sequence[int] = (16, 32),
    downscale: int | None = None,
    floor: float = 1e-3,
) -> float:
    """RMS difference, in dB, between the binned spatio-temporal power spectra of output and source.

    Both spectra come from :func:`st_power_spectrum` with the same cuboid and downscale
    factor, so clips of different sizes and lengths compare. The DC bin is left out; each
    bin's power gets ``floor`` times the source's mean bin power added before the log, which
    bounds the distance when the output has no power in a bin (a frozen clip). 0 dB is
    identical statistics.

    Parameters
    ----------
    output, source : ndarray
        ``(T, H, W[, C])`` clips.
    cuboid : (frames, pixels)
        Cuboid size; shrunk to fit the shorter or smaller of the two clips.
    downscale : int, optional
        Area-downscale factor (default ``max(1, min(H, W) // 128)`` of the source).
    floor : float
        Relative power floor.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> clip = rng.normal(128, 20, (16, 32, 32)).clip(0, 255)
    >>> spectrum_distance(clip, clip, cuboid=(8, 16))
    0.0
    """
    output = check_frames(output, name="output", min_frames=2)
    source = check_frames(source, name="source", min_frames=2)
    floor = _POSITIVE.check("floor", floor)
    f = _auto_downscale(source, downscale)
    ct, cs = _pair("cuboid", cuboid, 2)
    go, gs = _grey(output, f), _grey(source, f)
    ct = min(ct, go.shape[0], gs.shape[0])
    cs = min(cs, *go.shape[1:], *gs.shape[1:])
    if ct < 4 or cs < 4:
        raise InvalidArgumentError(
            f"clips too small for a power spectrum: need at least 4 frames and 4x4 pixels "
            f"after downscaling by {f}, got {ct} frames and {cs} pixels"
        )
    po, ps = _spectrum(go, ct, cs), _spectrum(gs, ct, cs)
    mask = np.ones(po.shape, bool)
    mask[0, 0] = False
    fl = floor * float(ps[mask].mean()) + 1e-12
    d = 10.0 * np.log10((po[mask] + fl) / (ps[mask] + fl))
    return float(np.sqrt(np.mean(d * d)))


# -- likeness: patch coherence and completeness ----------------------------------------------
def _patches(grey: np.ndarray, pt: int, ps: int, st: int, ss: int) -> tuple[np.ndarray, tuple[int, int, int]]:
    from numpy.lib.stride_tricks import sliding_window_view

    t, h, w = grey.shape
    if t < pt or h < ps or w < ps:
        raise InvalidArgumentError(
            f"clip ({t} frames of {w}x{h} after downscaling) is smaller than one patch ({pt} frames of {ps}x{ps})"
        )
    v = sliding_window_view(grey, (pt, ps, ps))[::st, ::ss, ::ss]
    return v, v.shape[:3]


def _project(view: np.ndarray, idx: np.ndarray | None, mean: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Patches of ``view`` (all, or the flat indices ``idx``) centred and projected on ``basis``."""
    grid = view.shape[:3]
    d = mean.size
    if idx is None:
        idx = np.arange(int(np.prod(grid)))
    out = np.empty((len(idx), basis.shape[1]), np.float32)
    for i in range(0, len(idx), 8192):
        sel = np.unravel_index(idx[i : i + 8192], grid)
        p = view[sel].reshape(-1, d) - mean
        out[i : i + len(p)] = p @ basis
    return out


def _nn_dist(q: np.ndarray, db: np.ndarray) -> np.ndarray:
    """Euclidean distance from each row of ``q`` to its nearest row of ``db`` (brute force, chunked).

    The search runs on float32 dot products; the winner's distance is then recomputed
    exactly, so a patch found in ``db`` has distance 0.
    """
    best = np.full(len(q), np.inf, np.float32)
    arg = np.zeros(len(q), np.int64)
    dbn = np.einsum("ij,ij->i", db, db)
    for j in range(0, len(db), 16384):
        d2 = dbn[None, j : j + 16384] - 2.0 * (q @ db[j : j + 16384].T)
        k = d2.argmin(axis=1)
        v = d2[np.arange(len(q)), k]
        better = v < best
        best[better] = v[better]
        arg[better] = k[better] + j
    diff = q.astype(np.float64) - db[arg].astype(np.float64)
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def patch_distances(
    output: np.ndarray,
    source: np.ndarray,
    *,
    patch: Sequence[int] = (3, 5),
    stride: Sequence[int] = (2, 3),
    n_samples: int = 1000,
    n_components: int = 16,
    downscale: int | None = None,
    seed: int = 0,
) -> tuple[float, float]:
    """Nearest-neighbour spatio-temporal patch coherence and completeness, ``(coherence, completeness)``.

    Both clips become luma, area-downscaled by ``downscale``. A patch is ``patch[0]`` frames
    by ``patch[1]`` x ``patch[1]`` pixels, taken on a grid of ``stride[0]`` frames and
    ``stride[1]`` pixels. Patches are centred on the source's mean patch and projected on
    the source patches' ``n_components`` leading principal components. *Coherence*:
    ``n_samples`` output patches drawn at random (``seed``) from the output's grid, each
    matched to its nearest patch of the source grid. *Completeness*: the same with the roles
    swapped. Each is the mean nearest distance expressed as RMS grey levels per patch pixel
    (0 = every patch found exactly).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clip = rng.integers(0, 256, (8, 16, 16)).astype(np.uint8)
    >>> [round(v, 3) for v in patch_distances(clip, clip, n_samples=50, downscale=1)]
    [0.0, 0.0]
    """
    output = check_frames(output, name="output")
    source = check_frames(source, name="source")
    pt, ps = _pair("patch", patch, 1)
    st, ss = _pair("stride", stride, 1)
    n_samples = check_int("n_samples", n_samples, 1)
    n_components = check_int("n_components", n_components, 1)
    seed = check_int("seed", seed, 0)
    f = _auto_downscale(source, downscale)
    vo, go = _patches(_grey(output, f), pt, ps, st, ss)
    vs, gs = _patches(_grey(source, f), pt, ps, st, ss)
    d = pt * ps * ps
    rng = np.random.default_rng(seed)
    n_src, n_out = int(np.prod(gs)), int(np.prod(go))
    fit_idx = rng.choice(n_src, size=min(n_src, 20000), replace=False)
    sel = np.unravel_index(fit_idx, gs)
    fit = vs[sel].reshape(-1, d).astype(np.float64)
    mean = fit.mean(axis=0)
    cov = np.cov(fit - mean, rowvar=False) if len(fit) > 1 else np.zeros((d, d))
    cov = np.atleast_2d(cov)
    vals, vecs = np.linalg.eigh(cov)
    k = min(n_components, d)
    basis = np.ascontiguousarray(vecs[:, ::-1][:, :k]).astype(np.float32)
    mean32 = mean.astype(np.float32)
    src_all = _project(vs, None, mean32, basis)
    out_all = _project(vo, None, mean32, basis)
    q_out = out_all[rng.choice(n_out, size=min(n_out, n_samples), replace=False)]
    q_src = src_all[rng.choice(n_src, size=min(n_src, n_samples), replace=False)]
    coherence = float(_nn_dist(q_out, src_all).mean()) / math.sqrt(d)
    completeness = float(_nn_dist(q_src, out_all).mean()) / math.sqrt(d)
    return coherence, completeness


def patch_coherence(output: np.ndarray, source: np.ndarray, **options: Any) -> float:
    """Mean distance from output patches to their nearest source patch (see :func:`patch_distances`).

    Low: every piece of the output looks like some piece of the source.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (8, 16, 16)).astype(np.uint8)
    >>> round(patch_coherence(clip, clip, n_samples=50, downscale=1), 3)
    0.0
    """
    return patch_distances(output, source, **options)[0]


def patch_completeness(output: np.ndarray, source: np.ndarray, **options: Any) -> float:
    """Mean distance from source patches to their nearest output patch (see :func:`patch_distances`).

    Low: every piece of the source shows up somewhere in the output.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (8, 16, 16)).astype(np.uint8)
    >>> round(patch_completeness(clip, clip, n_samples=50, downscale=1), 3)
    0.0
    """
    return patch_distances(output, source, **options)[1]


# -- coverage and repetition ------------------------------------------------------------------
def index_coverage(indices: Any, n_source: int) -> float:
    """Share of the ``n_source`` source frames (or tiles) that appear in ``indices``.

    Examples
    --------
    >>> index_coverage([0, 1, 1, 3], 8)
    0.375
    """
    n_source = check_int("n_source", n_source, 1)
    idx = np.asarray(indices)
    if idx.size == 0:
        raise InvalidArgumentError("indices is empty")
    if idx.dtype.kind not in "ui":
        raise ArgumentTypeError(f"indices must be integers, not {idx.dtype}")
    if idx.min() < 0 or idx.max() >= n_source:
        raise InvalidArgumentError(f"indices must lie in 0..{n_source - 1}, found {int(idx.min())}..{int(idx.max())}")
    return float(np.unique(idx).size) / n_source


def frame_coverage(output: np.ndarray, source: np.ndarray) -> float:
    """Share of source frames that are the nearest source frame of at least one output frame.

    Frames are compared as luma thumbnails (longer side 32 pixels) by Euclidean distance.
    1 when the output shows every source frame; ``1/T`` for a frozen frame.

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (10, 8, 8)).astype(np.uint8)
    >>> frame_coverage(clip, clip), frame_coverage(clip[[3] * 10], clip)
    (1.0, 0.1)
    """
    output = check_frames(output, name="output")
    source = check_frames(source, name="source")
    _same_size(output, source, "frame_coverage")
    size = _thumb_size(source.shape)
    to = _grey(output, size=size).reshape(output.shape[0], -1)
    ts = _grey(source, size=size).reshape(source.shape[0], -1)
    return index_coverage(_nearest_rows(to, ts), source.shape[0])


def _nearest_rows(q: np.ndarray, db: np.ndarray) -> np.ndarray:
    q64, db64 = q.astype(np.float64), db.astype(np.float64)
    dbn = np.einsum("ij,ij->i", db64, db64)
    out = np.empty(len(q), np.int64)
    for i in range(0, len(q), 1024):
        out[i : i + 1024] = np.argmin(dbn[None, :] - 2.0 * (q64[i : i + 1024] @ db64.T), axis=1)
    return out


def lattice_correlation(frames: np.ndarray, period: int | Sequence[int]) -> tuple[float, float]:
    """Spatial repetition at a lattice period: ``(along y, along x)`` correlation of each frame
    with itself shifted by ``period`` ``(py, px)``, averaged over frames.

    The luma of each frame, minus its mean, is correlated (Pearson) with the same frame
    moved by ``py`` rows, and by ``px`` columns. A natural texture is near 0 at any lag
    longer than its own structures; content that repeats at every tile of a lattice raises
    it (a lattice of one tile: 1). Compare with the source at the same lags.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> tile = rng.integers(0, 256, (1, 8, 8)).astype(np.uint8)
    >>> tiled = np.tile(tile, (1, 4, 4))
    >>> [round(v, 3) for v in lattice_correlation(tiled, 8)]
    [1.0, 1.0]
    >>> noise = rng.integers(0, 256, (2, 32, 32)).astype(np.uint8)
    >>> bool(max(lattice_correlation(noise, 8)) < 0.1)
    True
    """
    frames = check_frames(frames)
    py, px = _pair("period", period, 1)
    t, h, w = frames.shape[:3]
    if py >= h or px >= w:
        raise InvalidArgumentError(f"period {py}x{px} must be smaller than the {h}x{w} frame")
    acc = np.zeros(2)
    for _, chunk in _chunks(frames):
        for g in _grey(chunk):
            g = g - g.mean()
            for k, (a, b) in enumerate(((g[:-py], g[py:]), (g[:, :-px], g[:, px:]))):
                den = np.sqrt(float((a * a).mean()) * float((b * b).mean()))
                acc[k] += float((a * b).mean()) / den if den > 0 else 0.0
    return float(acc[0] / t), float(acc[1] / t)


def lattice_lags(tile: int | Sequence[int]) -> list[tuple[int, int]]:
    """The lags of a ``(th, tw)`` cell lattice at which :func:`lattice_prominence` looks:
    ``(0, tw), (th, 0), (th, tw), (0, 2 tw), (2 th, 0)``."""
    th, tw = _pair("tile", tile, 1)
    return [(0, tw), (th, 0), (th, tw), (0, 2 * tw), (2 * th, 0)]


def _autocorrelation(g: np.ndarray, max_dy: int, max_dx: int) -> np.ndarray:
    """Normalised autocorrelation of one mean-removed luma frame ``g (H, W)`` at lags
    ``dy in [0, max_dy]``, ``dx in [-max_dx, max_dx]``: ``(max_dy + 1, 2 max_dx + 1)``, the mean
    product over each lag's overlap divided by the frame's variance (zero-padded FFT, so no
    wrap-around)."""
    h, w = g.shape
    fh, fw = 2 * h, 2 * w
    spec = np.fft.rfft2(g, (fh, fw))
    ac = np.fft.irfft2(spec * np.conj(spec), (fh, fw))
    dys = np.arange(max_dy + 1)
    dxs = np.arange(-max_dx, max_dx + 1)
    raw = ac[dys[:, None], dxs[None, :] % fw]
    count = (h - dys)[:, None] * (w - np.abs(dxs))[None, :]
    var = float((g * g).mean())
    return raw / count / var if var > 0 else np.zeros_like(raw)


def lattice_prominence(
    frames: np.ndarray, tile: int | Sequence[int], *, max_frames: int = 30, per_lag: bool = False
) -> float | None | tuple[float | None, dict]:
    """How much a cell lattice ``(th, tw)`` stands out in the output's autocorrelation.

    For each frame (at most ``max_frames``, evenly spread), the normalised autocorrelation of
    its mean-removed luma at each lattice lag (:func:`lattice_lags`) minus the mean of the
    autocorrelation over a ring of lags ``3 <= |d - lag| <= max(6, min(th, tw) / 4)`` around
    it; the median over lags and frames. Content repeated at every cell makes a peak at the
    lattice lags that its surroundings do not share (a wallpaper of one tile: about 1); a
    natural texture, or a smooth correlation that merely decays with distance, gives about 0.
    Lags whose ring does not fit inside the frame with at least a quarter of the frame
    overlapping (in each direction) are left out; None when none fits.

    With ``per_lag`` returns ``(prominence, {"(dy, dx)": median over frames})``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> tile = rng.integers(0, 256, (1, 16, 16)).astype(np.uint8)
    >>> round(lattice_prominence(np.tile(tile, (1, 6, 6)), 16), 2)
    1.0
    >>> noise = rng.integers(0, 256, (2, 96, 96)).astype(np.uint8)
    >>> abs(lattice_prominence(noise, 16)) < 0.02
    True
    """
    frames = check_frames(frames)
    th, tw = _pair("tile", tile, 1)
    max_frames = check_int("max_frames", max_frames, 1)
    t, h, w = frames.shape[:3]
    r = max(6.0, min(th, tw) / 4.0)
    ri = int(np.ceil(r))
    lags = [(dy, dx) for dy, dx in lattice_lags((th, tw)) if dy + ri <= h - h // 4 and dx + ri <= w - w // 4]
    if not lags:
        return (None, {}) if per_lag else None
    max_dy = max(dy for dy, _ in lags) + ri
    max_dx = max(dx for _, dx in lags) + ri
    oy, ox = np.mgrid[-ri : ri + 1, -ri : ri + 1]
    dist = np.sqrt(oy * oy + ox * ox)
    ring = (dist >= 3) & (dist <= r)
    ry, rx = oy[ring], ox[ring]
    idx = np.unique(np.linspace(0, t - 1, min(max_frames, t)).round().astype(int))
    values = np.empty((len(idx), len(lags)))
    for fi, k in enumerate(idx):
        g = _grey(frames[k : k + 1])[0].astype(np.float64)
        g -= g.mean()
        ac = _autocorrelation(g, max_dy, max_dx)
        for li, (dy, dx) in enumerate(lags):
            # the autocorrelation is symmetric: a lag of negative dy is the mirrored lag
            yy, xx = dy + ry, dx + rx
            xx = np.where(yy < 0, -xx, xx)
            yy = np.abs(yy)
            values[fi, li] = ac[dy, dx + max_dx] - ac[yy, xx + max_dx].mean()
    prom = float(np.median(values))
    if per_lag:
        return prom, {f"({dy}, {dx})": float(np.median(values[:, li])) for li, (dy, dx) in enumerate(lags)}
    return prom


def repetition_profile(
    output: np.ndarray, *, source: np.ndarray | None = None, max_lag: int | None = None
) -> np.ndarray:
    """Mean frame difference at each lag, over the reference's median consecutive-frame difference.

    ``profile[L - 1]`` is the mean over ``t`` of the RMS difference between luma thumbnails
    (longer side 32 pixels) of output frames ``t`` and ``t + L``, divided by the median
    difference between consecutive thumbnails of ``source`` (of the output when None).

    Parameters
    ----------
    output : ndarray
        ``(T, H, W[, C])`` clip, at least 2 frames.
    source : ndarray, optional
        Reference clip (any size) for the normalisation.
    max_lag : int, optional
        Largest lag (default ``T // 2``, at most ``T - 1``).

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (12, 8, 8)).astype(np.uint8)
    >>> prof = repetition_profile(np.concatenate([clip[:4]] * 3))
    >>> int(np.argmin(prof)) + 1, float(prof.min())
    (4, 0.0)
    """
    output = check_frames(output, name="output", min_frames=2)
    t = output.shape[0]
    max_lag = max(1, t // 2) if max_lag is None else check_int("max_lag", max_lag, 1, t - 1)
    to = _grey(output, size=_thumb_size(output.shape)).reshape(t, -1).astype(np.float64)
    to -= to.mean(axis=0)  # smaller norms: less cancellation in the Gram-matrix distances
    if source is None:
        ref_thumbs = to
    else:
        source = check_frames(source, name="source", min_frames=2)
        ref_thumbs = _grey(source, size=_thumb_size(source.shape)).reshape(source.shape[0], -1).astype(np.float64)
    dr = np.diff(ref_thumbs, axis=0)
    ref = float(np.median(np.sqrt(np.mean(dr * dr, axis=1))))
    if ref <= 0:
        ref = 1e-3  # a frozen reference: any change counts as large
    d = to.shape[1]
    norms = np.einsum("ij,ij->i", to, to)
    sums = np.zeros(max_lag + 1)
    counts = np.zeros(max_lag + 1)
    for i0 in range(0, t, 512):
        i1 = min(t, i0 + 512)
        j1 = min(t, i1 + max_lag)
        d2 = norms[i0:i1, None] + norms[None, i0:j1] - 2.0 * (to[i0:i1] @ to[i0:j1].T)
        lag = np.arange(i0, j1)[None, :] - np.arange(i0, i1)[:, None]
        m = (lag >= 1) & (lag <= max_lag)
        rms = np.sqrt(np.maximum(d2[m], 0.0) / d)
        sums += np.bincount(lag[m], weights=rms, minlength=max_lag + 1)
        counts += np.bincount(lag[m], minlength=max_lag + 1)
    prof = sums[1:] / counts[1:] / ref
    prof[prof < 1e-6] = 0.0  # rounding of the Gram-matrix distances
    return prof


def repetition_lag(
    output: np.ndarray, *, source: np.ndarray | None = None, tolerance: float = 0.25, max_lag: int | None = None
) -> int | None:
    """Earliest lag at which the output repeats itself, or None when it does not within ``max_lag``.

    The output repeats at lag ``L`` when :func:`repetition_profile` at ``L`` is at most
    ``tolerance`` (a fraction of the reference's median consecutive-frame difference).

    Examples
    --------
    >>> clip = np.random.default_rng(0).integers(0, 256, (30, 8, 8)).astype(np.uint8)
    >>> repetition_lag(np.concatenate([clip[:5]] * 6), source=clip), repetition_lag(clip)
    (5, None)
    """
    tolerance = _POSITIVE.check("tolerance", tolerance)
    prof = repetition_profile(output, source=source, max_lag=max_lag)
    hits = np.flatnonzero(prof <= tolerance)
    return int(hits[0]) + 1 if hits.size else None


# -- everything at once ---------------------------------------------------------------------
def evaluate(
    output: np.ndarray,
    source: np.ndarray,
    *,
    labels: np.ndarray | None = None,
    wrap: bool = False,
    events: Sequence[int] | None = None,
    window: int = 25,
    downscale: int | None = None,
    seed: int = 0,
    n_samples: int = 1000,
    period: Sequence[int] | None = None,
    lattice: Sequence[int] | None = None,
) -> dict[str, Any]:
    """Every metric of this module for one output against its source, as a JSON-ready dict.

    ``output_size`` and ``source_size`` are ``[height, width]``. Size-bound metrics
    (stability, frame coverage) are None when the frame sizes differ;
    when the output holds NaN/inf, only stability is computed. With ``period`` ``(py, px)``
    (a tile lattice) the lattice correlation of the output and of the source (None where
    a frame is not larger than the period) at those lags. With ``lattice`` ``(th, tw)`` (the
    player's cell lattice) the :func:`lattice_prominence` of the output and of the source (None
    where no lag fits the frame), with the output's figure per lag.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clip = rng.integers(0, 256, (20, 32, 32, 3)).astype(np.uint8)
    >>> rep = evaluate(clip, clip, window=20)
    >>> rep["stability"]["final_ratio"], rep["frame_coverage"], rep["spectrum_distance_db"]
    (1.0, 1.0, 0.0)
    """
    source = check_frames(source, name="source", min_frames=2)
    output = check_frames(output, name="output", min_frames=2, allow_nonfinite=True)
    same = output.shape[1:] == source.shape[1:]
    report: dict[str, Any] = {
        "output_frames": int(output.shape[0]),
        "source_frames": int(source.shape[0]),
        "output_size": [int(output.shape[1]), int(output.shape[2])],  # (height, width)
        "source_size": [int(source.shape[1]), int(source.shape[2])],
    }
    report["stability"] = stability(output, source, window=window).as_dict() if same else None
    if report["stability"] is not None and report["stability"]["nonfinite_frames"]:
        return report
    output = check_frames(output, name="output", min_frames=2)
    if labels is not None or wrap:
        r = seam_visibility(output, labels, wrap=wrap)
        report["seam_visibility"] = {"mean": float(r.mean()), "max": float(r.max())}
    else:
        report["seam_visibility"] = None
    if events:
        r = temporal_discontinuity(output, events, source=source)
        report["temporal_discontinuity"] = {
            "events": [int(e) for e in events],
            "ratios": r.tolist(),
            "max": float(r.max()),
        }
    else:
        report["temporal_discontinuity"] = None
    report["frame_step_ratio"] = frame_step_ratio(output, source)
    report["spectrum_distance_db"] = spectrum_distance(output, source, downscale=downscale)
    coh, comp = patch_distances(output, source, downscale=downscale, seed=seed, n_samples=n_samples)
    report["patch_coherence"] = coh
    report["patch_completeness"] = comp
    report["frame_coverage"] = frame_coverage(output, source) if same else None
    report["repetition_lag"] = repetition_lag(output, source=source)
    report["out_of_gamut_share"] = out_of_gamut_share(output, source)
    report["source_out_of_gamut_share"] = source_gamut_share(source)
    if period is not None:
        py, px = _pair("period", period, 1)

        def correlation(frames: np.ndarray) -> list[float] | None:
            if frames.shape[1] <= py or frames.shape[2] <= px:
                return None  # no lag of the period fits inside the frame
            return list(lattice_correlation(frames[:: max(1, len(frames) // 30)], (py, px)))

        report["lattice_correlation"] = {
            "period": [py, px],
            "output": correlation(output),
            "source": correlation(source),
        }
    if lattice is not None:
        th, tw = _pair("lattice", lattice, 1)
        prom, lags = lattice_prominence(output, (th, tw), per_lag=True)
        report["lattice_prominence"] = {
            "tile": [th, tw],
            "output": prom,
            "lags": lags,
            "source": lattice_prominence(source, (th, tw)),
        }
    return report


# -- colours the source never had -----------------------------------------------------------
#: bits per channel of the colour bins (bins 8 levels wide)
GAMUT_BITS = 5


def _colour_bins(frames: np.ndarray) -> np.ndarray:
    """Each pixel's colour bin, ``(r >> 3) * 1024 + (g >> 3) * 32 + (b >> 3)`` (grey: r = g = b)."""
    f = np.asarray(frames)
    if f.dtype != np.uint8:
        f = np.clip(np.rint(f), 0, 255).astype(np.uint8)
    if f.ndim == 3:
        f = f[..., None]
    f = f.reshape(-1, f.shape[-1]) >> (8 - GAMUT_BITS)
    if f.shape[1] == 1:
        f = np.repeat(f, 3, axis=1)
    n = 1 << GAMUT_BITS
    return (f[:, 0].astype(np.int32) * n + f[:, 1]) * n + f[:, 2]


def colour_set(frames: np.ndarray) -> np.ndarray:
    """The colour bins ``frames`` occupy, grown by one bin in every direction (26 neighbours):
    a bool per bin of :func:`_colour_bins` (``32**3``), the set :func:`out_of_gamut_share` tests against."""
    n = 1 << GAMUT_BITS
    occ = np.zeros(n**3, bool)
    for lo in range(0, len(frames), _CHUNK):
        occ[_colour_bins(frames[lo : lo + _CHUNK])] = True
    occ = np.pad(occ.reshape(n, n, n), 1)
    grown = np.zeros((n, n, n), bool)
    for dr in range(3):
        for dg in range(3):
            for db in range(3):
                grown |= occ[dr : dr + n, dg : dg + n, db : db + n]
    return grown.reshape(-1)


def _share_outside(frames: np.ndarray, colours: np.ndarray) -> float:
    outside = total = 0
    for lo in range(0, len(frames), _CHUNK):
        bins = _colour_bins(frames[lo : lo + _CHUNK])
        outside += int(np.count_nonzero(~colours[bins]))
        total += bins.size
    return outside / max(total, 1)


def out_of_gamut_share(output: np.ndarray, source: np.ndarray) -> float:
    """Share of the output's pixels whose colour the source never had.

    A colour is the source's when its 8-level RGB bin, or a neighbouring bin, holds a pixel
    of the source. Measured against each half of the source in turn (first and second half
    of its frames) and averaged, so that it compares directly with :func:`source_gamut_share`,
    the source's own level: an output at or below it has no colours the clip never had.

    Examples
    --------
    >>> red = np.zeros((10, 4, 4, 3), np.uint8); red[..., 0] = 200
    >>> cyan = red.copy(); cyan[..., 0] = 0; cyan[..., 1:] = 200
    >>> out_of_gamut_share(red, red), out_of_gamut_share(np.concatenate([red, cyan]), red)
    (0.0, 0.5)
    """
    output = check_frames(output, name="output", min_frames=1)
    source = check_frames(source, name="source", min_frames=2)
    half = len(source) // 2
    return 0.5 * sum(_share_outside(output, colour_set(part)) for part in (source[:half], source[half:]))


def source_gamut_share(source: np.ndarray) -> float:
    """The source's own out-of-gamut level: each half of its frames measured against the other
    (:func:`out_of_gamut_share`), averaged. Colours that appear in one half only count."""
    source = check_frames(source, name="source", min_frames=2)
    half = len(source) // 2
    a, b = source[:half], source[half:]
    return 0.5 * (_share_outside(b, colour_set(a)) + _share_outside(a, colour_set(b)))


def _json_float(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None
