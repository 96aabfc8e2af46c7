"""Seams in space and in time: seam visibility across a cell grid, the jump at an event (loop
wrap, reversal, transition) and the typical frame step, each against the source.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ...checks import check_frames
from ...errors import ArgumentTypeError, InvalidArgumentError
from ...framestats import float_chunks, step_rms
from ._common import POSITIVE, int_pair, reference_step


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
    h, w = int_pair("shape", tuple(shape), 1)
    th, tw = int_pair("tile", tile, 1)
    oy, ox = int_pair("offset", tuple(offset), 0)
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
    eps = POSITIVE.check("eps", eps)
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
    for i, f in float_chunks(frames):
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
    ref = reference_step(
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
    return float(np.median(step_rms(output))) / reference_step(source, "source")
