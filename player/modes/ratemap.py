"""Rate maps ``M(y, x)`` for mode ``evolve``: how fast each output pixel runs through the
source's evolution (the seed's section 6: ``source time = t * M``; 1 = as captured, 2 =
twice as fast, 0 = frozen at the first frame).

Generators for the seed's phenomenological controls (light fall-off from a point source,
a painted mask, any grey image), plus :func:`check_rate_map`, the validation every rate
map goes through. All numpy; images are passed in as arrays (the CLI decodes files).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ...checks import MAX_SIDE, Size
from ...errors import ArgumentTypeError, InvalidArgumentError

#: Largest rate accepted: a pixel 64 times faster than the source.
MAX_RATE = 64.0
#: The output's ``shape`` every generator takes: (height, width), each side in 1..MAX_SIDE.
SHAPE = Size(MAX_SIDE)


def check_rate_map(rate: object, shape: tuple[int, int], *, name: str = "rate_map") -> np.ndarray:
    """``rate`` as a C-contiguous ``(H, W)`` float32 copy, or a ValueError/TypeError naming ``name``.

    Examples
    --------
    >>> check_rate_map(np.ones((2, 3)), (2, 3)).dtype
    dtype('float32')
    """
    if not isinstance(rate, np.ndarray):
        raise ArgumentTypeError(f"{name} must be a numpy array of shape {tuple(shape)}, not {type(rate).__name__}")
    if rate.dtype.kind not in "fiub":
        raise ArgumentTypeError(f"{name} must hold numbers, not {rate.dtype}")
    if rate.shape != tuple(shape):
        raise InvalidArgumentError(
            f"{name} is {_wh(rate.shape)} but the output is {shape[1]}x{shape[0]} (W x H); they must match"
        )
    arr = rate.astype(np.float64)
    if not np.isfinite(arr).all():
        raise InvalidArgumentError(f"{name} holds NaN or infinite values")
    if arr.size and (arr.min() < 0 or arr.max() > MAX_RATE):
        raise InvalidArgumentError(
            f"{name} values must lie in [0, {MAX_RATE:g}], found {arr.min():.4g}..{arr.max():.4g}"
        )
    return np.ascontiguousarray(arr, dtype=np.float32)


def uniform(shape: Sequence[int], rate: float = 1.0) -> np.ndarray:
    """A constant map."""
    h, w = SHAPE.check("shape", shape)
    return np.full((h, w), _rate("rate", rate), np.float32)


def halves(shape: Sequence[int], left: float = 2.0, right: float = 1.0) -> np.ndarray:
    """``left`` on the left half (columns ``< W // 2``), ``right`` on the right half.

    Examples
    --------
    >>> halves((1, 4), 2, 1).tolist()
    [[2.0, 2.0, 1.0, 1.0]]
    """
    h, w = SHAPE.check("shape", shape)
    m = np.full((h, w), _rate("right", right), np.float32)
    m[:, : w // 2] = _rate("left", left)
    return m


def point_light(
    shape: Sequence[int], center: Sequence[float], height: float, *, max_rate: float = 2.0, min_rate: float = 0.0
) -> np.ndarray:
    """Rate from the light a point source casts on the plane (the seed's eq. 9).

    Irradiance at pixel ``p`` from a light at ``(cx, cy)`` raised ``height`` pixels above the
    plane is ``cos(theta) / r^2``; the seed squares it for a more dramatic fall-off. The map
    is scaled so that the brightest pixel gets ``max_rate`` and no light gives ``min_rate``.

    Examples
    --------
    >>> m = point_light((5, 5), (2, 2), 3.0, max_rate=2.0)
    >>> float(m[2, 2]), bool(m[0, 0] < m[1, 1] < m[2, 2])
    (2.0, True)
    """
    h, w = SHAPE.check("shape", shape)
    try:
        cx, cy = (float(v) for v in center)
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"center must be (x, y) in pixels, not {center!r}") from None
    if not (np.isfinite(cx) and np.isfinite(cy)):
        raise InvalidArgumentError(f"center must be finite, not {center!r}")
    height = _rate("height", height, hi=1e6)
    if height <= 0:
        raise InvalidArgumentError(f"height must be positive, not {height!r}")
    max_rate, min_rate = _rate("max_rate", max_rate), _rate("min_rate", min_rate)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    r2 = (xx - cx) ** 2 + (yy - cy) ** 2 + height**2
    cos = height / np.sqrt(r2)
    light = (cos / r2) ** 2
    light /= light.max()
    return (min_rate + (max_rate - min_rate) * light).astype(np.float32)


def from_image(image: np.ndarray, *, low: float = 0.0, high: float = 2.0) -> np.ndarray:
    """Rate from a grey (or RGB, averaged) image: black gives ``low``, white ``high``.

    uint8 images are read on 0..255; float images on 0..1. Also the way to use a painted mask.

    Examples
    --------
    >>> from_image(np.array([[0, 255]], np.uint8), low=1, high=3).tolist()
    [[1.0, 3.0]]
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (1, 3, 4):
        img = img[..., :3].mean(axis=2) if img.shape[2] >= 3 else img[..., 0]
    if img.ndim != 2:
        raise InvalidArgumentError(f"image must be (H, W) or (H, W, 1|3|4), not shape {np.asarray(image).shape}")
    if img.dtype.kind not in "fiub":
        raise ArgumentTypeError(f"image must hold numbers, not {img.dtype}")
    v = img.astype(np.float64)
    if np.asarray(image).dtype == np.uint8:
        v = v / 255.0
    if not np.isfinite(v).all() or v.min() < 0 or v.max() > 1:
        raise InvalidArgumentError("image values must be finite, on 0..255 (uint8) or 0..1 (float)")
    low, high = _rate("low", low), _rate("high", high)
    return (low + (high - low) * v).astype(np.float32)


def _rate(name: str, v: object, hi: float = MAX_RATE) -> float:
    try:
        f = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{name} must be a number, not {v!r}") from None
    if not np.isfinite(f) or f < 0 or f > hi:
        raise InvalidArgumentError(f"{name} must be a finite number in [0, {hi:g}], not {v!r}")
    return f


def _wh(shape: tuple[int, ...]) -> str:
    return f"{shape[1]}x{shape[0]} (W x H)" if len(shape) == 2 else f"of shape {shape}"
