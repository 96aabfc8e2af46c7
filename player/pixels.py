"""Output pixel formats: RGB (the default), or RGBA / BGRA with alpha 255, which game engines
upload as textures without a conversion. Every engine writes each format straight from its
kernel; :meth:`PixelFormat.from_rgb` is the numpy reference of that placement.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..errors import InvalidArgumentError


class PixelFormat(NamedTuple):
    """How an output pixel lies in memory: its bytes, where red, green and blue go, and
    where alpha (always 255) goes, if anywhere."""

    name: str
    bytes: int
    rgb: tuple[int, int, int]
    alpha: int | None

    @property
    def defines(self) -> dict[str, int]:
        """The kernel defines that place a pixel's bytes (``PIXEL_BYTES``, ``R_AT``, ...)."""
        return {
            "PIXEL_BYTES": self.bytes,
            "R_AT": self.rgb[0],
            "G_AT": self.rgb[1],
            "B_AT": self.rgb[2],
            "A_AT": -1 if self.alpha is None else self.alpha,
        }

    def from_rgb(self, rgb: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``rgb`` (..., 3) uint8 in this format, (..., bytes), into ``out`` when given.

        Examples
        --------
        >>> FORMATS["BGRA"].from_rgb(np.array([[10, 20, 30]], np.uint8)).tolist()
        [[30, 20, 10, 255]]
        """
        if out is None:
            out = np.empty(rgb.shape[:-1] + (self.bytes,), np.uint8)
        if self.name == "RGB":
            out[...] = rgb
            return out
        for c, at in enumerate(self.rgb):
            out[..., at] = rgb[..., c]
        out[..., self.alpha] = 255
        return out


#: the pixel formats a player writes: RGB (default), or RGBA / BGRA with alpha 255, which game
#: engines upload as textures without a conversion
FORMATS = {
    "RGB": PixelFormat("RGB", 3, (0, 1, 2), None),
    "RGBA": PixelFormat("RGBA", 4, (0, 1, 2), 3),
    "BGRA": PixelFormat("BGRA", 4, (2, 1, 0), 3),
}


def pixel_format(name: str | PixelFormat) -> PixelFormat:
    """The :class:`PixelFormat` named ``name`` (one of :data:`FORMATS`), else a ValueError."""
    if isinstance(name, PixelFormat):
        return name
    try:
        return FORMATS[name]
    except (KeyError, TypeError):
        raise InvalidArgumentError(f"format must be one of {tuple(FORMATS)}, not {name!r}") from None
