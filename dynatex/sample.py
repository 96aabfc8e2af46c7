"""Built-in sample clips, made procedurally so that ``dynatex demo`` needs no files."""

from __future__ import annotations

import numpy as np


def ripples(frames: int = 120, height: int = 96, width: int = 128, *, seed: int = 0) -> np.ndarray:
    """Water-like ripples: travelling waves in several directions, shaded blue-green.

    Periodic in time with incommensurate wave periods (so it never quite repeats), and
    spatially periodic over the frame, which suits every mode. Returns ``(T, H, W, 3)`` uint8.

    Examples
    --------
    >>> ripples(8, 16, 24).shape
    (8, 16, 24, 3)
    """
    rng = np.random.default_rng(seed)
    t = np.arange(frames, dtype=np.float32)[:, None, None]
    y = np.arange(height, dtype=np.float32)[None, :, None]
    x = np.arange(width, dtype=np.float32)[None, None, :]
    field = np.zeros((frames, height, width), np.float32)
    for i in range(6):
        kx = 2 * np.pi * rng.integers(1, 5) / width * rng.choice([-1, 1])
        ky = 2 * np.pi * rng.integers(1, 4) / height * rng.choice([-1, 1])
        period = rng.uniform(9.0, 31.0)
        field += np.sin(kx * x + ky * y - 2 * np.pi * t / period + rng.uniform(0, 2 * np.pi)) / (1 + 0.3 * i)
    field /= np.abs(field).max()
    caustic = np.abs(field) ** 0.5
    field = field + rng.normal(0, 0.03, field.shape).astype(np.float32)
    r = 30 + 60 * caustic + 20 * field
    g = 90 + 80 * caustic + 30 * field
    b = 140 + 70 * caustic + 40 * field
    return np.clip(np.stack([r, g, b], axis=-1), 0, 255).astype(np.uint8)
