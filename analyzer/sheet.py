"""Contact sheets: source frames beside output frames, one image to look at.

Metrics miss what an eye sees at once (a lattice, a repeated motif, a colour band), so
every synthesized output can be written as one PNG: ``rows`` moments of the output, each
beside the source frame of the same index (modulo the source's length), both at the same
pixel scale so a tile or a structure compares directly with the clip it came from.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import InvalidArgumentError

GAP = 8  # pixels between panels
LABEL_H = 14  # pixels of the caption above each row
MAX_WIDTH = 2400  # wider sheets are scaled down as a whole (both panels alike)


def _rgb(frame: np.ndarray) -> np.ndarray:
    f = np.asarray(frame)
    if f.dtype != np.uint8:
        f = np.clip(np.nan_to_num(f.astype(np.float64)), 0, 255).astype(np.uint8)
    if f.ndim == 2:
        f = f[..., None]
    return np.repeat(f, 3, axis=2) if f.shape[2] == 1 else f


def contact_sheet(
    source: np.ndarray, output: np.ndarray, path: str | os.PathLike | None = None, *, rows: int = 3, title: str = ""
) -> np.ndarray:
    """A sheet of ``rows`` moments: the source frame (left) beside the output frame (right).

    Parameters
    ----------
    source, output : ndarray
        ``(T, H, W[, C])`` clips (any sizes; shown at the same pixel scale).
    path : path, optional
        Where to write the PNG (Pillow).
    rows : int
        Moments shown, evenly spread over the output.
    title : str
        Caption of the first row (what was played).

    Returns
    -------
    ndarray
        The sheet, ``(H, W, 3)`` uint8.

    Examples
    --------
    >>> s = np.zeros((4, 8, 10, 3), np.uint8); o = np.full((6, 16, 20, 3), 200, np.uint8)
    >>> contact_sheet(s, o, rows=2).shape
    (68, 38, 3)
    """
    from PIL import Image, ImageDraw

    if rows < 1:
        raise InvalidArgumentError(f"rows must be at least 1, not {rows}")
    source, output = np.asarray(source), np.asarray(output)
    for name, clip in (("source", source), ("output", output)):
        if clip.ndim not in (3, 4) or clip.shape[0] < 1:
            raise InvalidArgumentError(f"{name} must be frames (T, H, W[, C]), not shape {clip.shape}")
    sh, sw = source.shape[1:3]
    oh, ow = output.shape[1:3]
    row_h = max(sh, oh) + LABEL_H
    width = sw + GAP + ow
    sheet = np.full((rows * row_h + (rows - 1) * GAP, width, 3), 255, np.uint8)
    idx = np.unique(np.linspace(0, output.shape[0] - 1, rows).round().astype(int))
    captions = []
    for r, k in enumerate(idx):
        y = r * (row_h + GAP) + LABEL_H
        sheet[y : y + sh, :sw] = _rgb(source[k % source.shape[0]])
        sheet[y : y + oh, sw + GAP :] = _rgb(output[k])
        captions.append((r * (row_h + GAP), k))
    img = Image.fromarray(sheet)
    draw = ImageDraw.Draw(img)
    for r, (y, k) in enumerate(captions):
        draw.text((2, y + 1), f"source {sw}x{sh}, frame {k % source.shape[0]}", fill=(0, 0, 0))
        head = f"{title}: " if title and r == 0 else ""
        draw.text((sw + GAP + 2, y + 1), f"{head}output {ow}x{oh}, frame {k}", fill=(0, 0, 0))
    if img.width > MAX_WIDTH:
        img = img.resize((MAX_WIDTH, round(img.height * MAX_WIDTH / img.width)), Image.Resampling.LANCZOS)
    if path is not None:
        img.save(os.fspath(path))
    return np.asarray(img)
