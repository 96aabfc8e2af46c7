"""Long-run stability: energy per time window against the source's, and frames holding NaN or inf."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...checks import check_frames, check_int
from ...errors import ArgumentTypeError, InvalidArgumentError
from ...framestats import CHUNK, float_chunks
from ._common import json_float
from .memo import remembered


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
    for i in range(0, arr.shape[0], CHUNK):
        c = arr[i : i + CHUNK]
        bad += int((~np.isfinite(c.reshape(c.shape[0], -1))).any(axis=1).sum())
    return bad


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
            "min_ratio": json_float(self.min_ratio),
            "max_ratio": json_float(self.max_ratio),
            "final_ratio": json_float(self.final_ratio),
            "stable": self.is_stable(),
            "source_min_ratio": json_float(self.source_min_ratio),
            "source_max_ratio": json_float(self.source_max_ratio),
            "bounds": [json_float(lo), json_float(hi)],
            "ratios": [json_float(v) for v in self.ratios],
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
    mean, src_energies = _source_energies(source)
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


@remembered
def _source_energies(source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The source's mean frame (float32) and each of its frames' dynamic energy about it."""
    mean = np.zeros(source.shape[1:], np.float64)
    for _, chunk in float_chunks(source):
        mean += chunk.sum(axis=0, dtype=np.float64)
    mean = (mean / source.shape[0]).astype(np.float32)
    return mean, _energies(source, mean)


def _energies(frames: np.ndarray, mean: np.ndarray) -> np.ndarray:
    out = np.empty(frames.shape[0], np.float64)
    for i, chunk in float_chunks(frames):
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
