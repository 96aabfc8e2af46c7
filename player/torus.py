"""Layouts of a quilted torus without a period: the torus's cells and a few jump cells.

A quilted tile set (``construction="quilted"``) is one large seamless torus cut into cells.
Laid in torus order, an output larger than the torus shows it again one period away (on a
256 px clip at 1920x1080 the frame correlates 0.8 with itself shifted by the period). Here
the output's cell columns follow a *column walk* through the torus's columns: column ``c``
is followed by ``c + 1``, except that at a few torus columns the walk may *jump*: the next
output column is then a jump strip that shows torus column ``c + 1`` left of a smoothed
minimum-error cut and torus column ``c'`` right of it, so that the walk goes on with
``c' + 1``. Rows follow a row walk the same way, and where a row jump crosses a column jump a
corner cell joins the four pieces. Every cell edge of the layout is then either the torus
continuing itself or a jump strip's own edge, which continues its neighbours exactly; the
only new seams are the jump cuts, chosen among all pairs of torus lines for the least
difference over the loop (like the quilt's own cuts) and cross-faded over
a third of the cell (:data:`JUMP_FADE`): a jump line runs across the whole output, and a
narrow fade showed the two lines' difference in brightness as a long straight edge.

Each walk jumps at random (:data:`JUMP_CHANCE` wherever its line has a jump, to one of its
jumps), so two places of a large output a period apart mostly show different parts of the
torus: a torus of ``n`` lines still shows one line at two places with a chance near ``1/n``,
which bounds how far the correlation at large shifts falls (and a torus of three lines or
fewer along an axis has no jump there that would not show a line again one or two cells on). Everything here is
computed once when a player opens (numpy, a few loop frames for the choice of jumps, every
loop frame for the jump cells) and drawn by the unchanged cell-grid gather: the jump cells
are extra cells in the gather's frame stack. A frame then reads more distinct cells (at
3840x2160 from a 576x720 torus, 22 MB of distinct tile data instead of 9 MB), which costs
cache traffic (benchmarks/bench_tiles.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

JUMP_CHANCE = 0.8  # chance that a walk jumps where its line has a jump
JUMPS_PER_LINE = 2  # jumps at most from (and to) each torus line
JUMP_FRAMES = 8  # loop frames compared when jumps are chosen and cut
JUMP_FADE = 1 / 3  # cross-fade across a jump cut, a share of the cell across it
JUMP_SMOOTH = 6.0  # rows of Gaussian smoothing of a jump cut (no stair-step teeth)


def _strips(tiles: np.ndarray, rows: int, cols: int, axis: int, frames: np.ndarray | None = None) -> np.ndarray:
    """Torus lines as strips, cut across: ``(n, L', length, across, 3)``; columns (``axis=1``:
    ``length = rows th``, ``across = tw``) or rows (``axis=0``, transposed: ``length = cols tw``)."""
    k, length, th, tw, c = tiles.shape
    t = tiles if frames is None else tiles[:, frames]
    f = t.shape[1]
    grid = t.reshape(rows, cols, f, th, tw, c)
    if axis == 1:  # column c: cells (0, c) .. (rows - 1, c) one below the other
        return grid.transpose(1, 2, 0, 3, 4, 5).reshape(cols, f, rows * th, tw, c)
    # row r, transposed: cells (r, 0) .. (r, cols - 1) one below the other, x and y swapped
    return grid.transpose(0, 2, 1, 4, 3, 5).reshape(rows, f, cols * tw, th, c)


def _min_path(err: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Minimum-error path through ``err (n, m)``, a column in ``lo .. hi - 1`` per row, moving
    at most one column from row to row (dynamic programming)."""
    n, m = err.shape
    e = np.full((n, m), np.inf)
    e[:, lo:hi] = err[:, lo:hi]
    acc = e[0].copy()
    back = np.zeros((n, m), np.int64)
    cols = np.arange(m)
    for i in range(1, n):
        left = np.r_[np.inf, acc[:-1]]
        right = np.r_[acc[1:], np.inf]
        stack = np.stack([left, acc, right])
        pick = np.argmin(stack, axis=0)
        back[i] = cols + pick - 1
        acc = stack[pick, cols] + e[i]
    path = np.empty(n, np.int64)
    path[-1] = int(np.argmin(acc))
    for i in range(n - 1, 0, -1):
        path[i - 1] = back[i, path[i]]
    return path


def cut_alpha(err: np.ndarray, *, fade: float, sigma: float = JUMP_SMOOTH) -> np.ndarray:
    """Share ``(n, m)`` of the strip left of a closed, smoothed minimum-error cut through
    ``err (n, m)`` (rows wrap: the strip is periodic along its length). The cut keeps
    ``fade / 2 + 1`` pixels from both sides and the share falls linearly over ``fade`` pixels
    across it, so the strip's first and last columns are the left and right strips alone.

    Examples
    --------
    >>> err = np.ones((6, 16)); err[:, 9] = 0
    >>> a = cut_alpha(err, fade=4.0)
    >>> a[0].round(2).tolist()
    [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.75, 0.5, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0]
    """
    n, m = err.shape
    margin = int(np.ceil(fade / 2)) + 1
    lo, hi = min(margin, m // 2), max(m - margin, m // 2 + 1)
    path = _min_path(np.asarray(err, np.float64), lo, hi).astype(np.float64) + 0.5  # the cut at pixel centres
    if sigma > 0 and n > 1:
        r = int(np.ceil(3 * sigma))
        k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
        path = np.convolve(np.pad(path, r, mode="wrap"), k / k.sum(), mode="valid")
    x = np.arange(m)[None, :] + 0.5
    return np.clip(0.5 - (x - path[:, None]) / max(fade, 1e-6), 0.0, 1.0)


def _errors(strips: np.ndarray) -> np.ndarray:
    """``(n, n)``: mean squared difference of strip ``a + 1`` and strip ``b`` along their
    quietest column pairs (the row minimum over the strip's middle half), the cost of a jump
    ``a -> b``; ``inf`` where the jump would be the torus itself (``b == a + 1``)."""
    n, _, length, across, _ = strips.shape
    q = across // 4
    mid = strips[:, :, ::2, q : across - q].astype(np.float32)  # every other line is enough to rank
    cost = np.full((n, n), np.inf)
    for a in range(n):
        d = mid[(a + 1) % n][None] - mid
        e = (d * d).sum(axis=(1, 4))  # (n, length, across/2)
        cost[a] = e.min(axis=2).mean(axis=1)
    cost[np.arange(n), (np.arange(n) + 1) % n] = np.inf
    return cost


def _choose(cost: np.ndarray, per_line: int = JUMPS_PER_LINE) -> tuple[np.ndarray, np.ndarray]:
    """Jumps ``(from, to)``, cheapest first, at most ``per_line`` from and to every line, none
    that shows a line again one or two cells on (``b`` within one line of ``a``: the walk
    ``a, (a + 1 | b), b + 1``), and none that closes a loop shorter than half the torus (a
    walk that took it twice in a row would repeat within a few cells: a jump ``a -> b`` brings
    the walk back to ``a`` after ``(a - b - 1) mod n + 2`` lines when it keeps going)."""
    n = len(cost)
    a_all, b_all = np.unravel_index(np.argsort(cost, axis=None, kind="stable"), cost.shape)
    used_a, used_b, out = np.zeros(n, int), np.zeros(n, int), []
    for a, b in zip(a_all.tolist(), b_all.tolist()):
        if not np.isfinite(cost[a, b]):
            break
        if used_a[a] >= per_line or used_b[b] >= per_line or (a - b - 1) % n + 2 < n / 2:
            continue
        if (b - a) % n in (0, 1, n - 1):
            continue
        used_a[a] += 1
        used_b[b] += 1
        out.append((a, b))
    out.sort()
    return np.array([a for a, _ in out], np.int64), np.array([b for _, b in out], np.int64)


@dataclass
class TorusJumps:
    """Jumps of a torus of ``rows x cols`` cells and the cells that draw them.

    ``col_from[j] -> col_to[j]``: column jump ``j`` (after torus column ``col_from[j]`` the
    jump strip, then ``col_to[j] + 1``); rows likewise. ``cells`` ``(n, L, th, tw, 3)``: the
    column jump strips (jump ``j``, torus row ``r`` at ``j * rows + r``), then the row jump
    strips (``j * cols + c``), then the corner cells (row jump ``i``, column jump ``j`` at
    ``i * n_col_jumps + j``). Cell indices of a layout count these after the torus's own
    ``base`` cells.
    """

    rows: int
    cols: int
    base: int
    col_from: np.ndarray
    col_to: np.ndarray
    row_from: np.ndarray
    row_to: np.ndarray
    cells: np.ndarray

    def index(self, row_walk: np.ndarray, col_walk: np.ndarray) -> np.ndarray:
        """The cell of every ``(row, column)`` of a layout: ``(len(row_walk), len(col_walk))``."""
        r = np.asarray(row_walk, np.int64)[:, None]
        c = np.asarray(col_walk, np.int64)[None, :]
        jc, jr = len(self.col_from), len(self.row_from)
        x_base = self.base
        y_base = x_base + jc * self.rows
        z_base = y_base + jr * self.cols
        rj, cj = -r - 1, -c - 1
        return np.where(
            r >= 0,
            np.where(c >= 0, r * self.cols + c, x_base + cj * self.rows + r),
            np.where(c >= 0, y_base + rj * self.cols + c, z_base + rj * jc + cj),
        )

    def walk(self, n: int, axis: int, rng: np.random.Generator, chance: float | None = None) -> np.ndarray:
        """A random walk of ``n`` lines along ``axis`` (1: columns, 0: rows): a torus line
        ``>= 0`` or a jump ``-1 - j``; it starts at a random torus line."""
        chance = JUMP_CHANCE if chance is None else chance
        lines = self.cols if axis == 1 else self.rows
        src, dst = (self.col_from, self.col_to) if axis == 1 else (self.row_from, self.row_to)
        out = np.empty(n, np.int64)
        out[0] = rng.integers(0, lines)
        for i in range(1, n):
            prev = int(out[i - 1])
            if prev < 0:
                out[i] = (int(dst[-prev - 1]) + 1) % lines
                continue
            js = np.flatnonzero(src == prev)
            out[i] = -1 - int(js[rng.integers(js.size)]) if js.size and rng.random() < chance else (prev + 1) % lines
        return out

    def broken_steps(self, walk: np.ndarray, axis: int) -> int:
        """Steps of ``walk`` that neither continue the torus nor take or leave a jump."""
        lines = self.cols if axis == 1 else self.rows
        src, dst = (self.col_from, self.col_to) if axis == 1 else (self.row_from, self.row_to)
        w = np.asarray(walk, np.int64)
        if w.size == 0:
            return 0
        bad = int(w[0] < 0 or w[0] >= lines) + int((w < -len(src)).sum() + (w >= lines).sum())
        if bad:
            return bad
        for prev, cur in zip(w[:-1], w[1:]):
            if prev < 0:
                bad += cur != (dst[-prev - 1] + 1) % lines
            elif cur < 0:
                bad += src[-cur - 1] != prev
            else:
                bad += cur != (prev + 1) % lines
        return int(bad)

    def decode(self, arrangement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ``(row_walk, col_walk)`` of a layout, read off its first column and first row
        (a walk starts on a torus line); indices outside the set read as broken lines."""
        a = np.asarray(arrangement, np.int64)
        jc = len(self.col_from)
        x_base = self.base
        y_base = x_base + jc * self.rows
        z_base = y_base + len(self.row_from) * self.cols
        first_col, first_row = a[:, 0], a[0, :]
        rows = np.where(
            first_col < x_base,
            first_col // self.cols,
            np.where((first_col >= y_base) & (first_col < z_base), -1 - (first_col - y_base) // self.cols, -(10**6)),
        )
        cols = np.where(
            first_row < x_base,
            first_row % self.cols,
            np.where(first_row < y_base, -1 - (first_row - x_base) // self.rows, -(10**6)),
        )
        return rows, cols


def torus_jumps(tiles: np.ndarray, torus: tuple[int, int], *, columns: bool = True, rows: bool = True) -> TorusJumps:
    """The jumps of a quilted torus (``tiles`` ``(rows cols, L, th, tw, 3)`` in torus order):
    up to :data:`JUMPS_PER_LINE` from each column and each row, the cheapest pairs of lines
    (:func:`_errors`, :func:`_choose`; none along an axis turned off), and their cells."""
    n_rows, n_cols = torus
    k, length, th, tw, _ = tiles.shape
    u = np.unique(np.linspace(0, length - 1, min(JUMP_FRAMES, length)).round().astype(int))
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    col_from, col_to = _choose(_errors(_strips(tiles, n_rows, n_cols, 1, u))) if columns else none
    row_from, row_to = _choose(_errors(_strips(tiles, n_rows, n_cols, 0, u))) if rows else none
    grid = tiles.reshape(n_rows, n_cols, length, th, tw, 3)
    cells = []
    col_alpha = []
    for a, b in zip(col_from, col_to):
        strip_a, strip_b = grid[:, (a + 1) % n_cols], grid[:, b]  # (rows, L, th, tw, 3)
        err = _cut_error(strip_a[:, u], strip_b[:, u]).reshape(n_rows * th, tw)
        alpha = cut_alpha(err, fade=JUMP_FADE * tw).reshape(n_rows, 1, th, tw, 1)
        col_alpha.append(alpha[:, 0, :, :, 0])
        cells.append(_blend(strip_a, strip_b, alpha))
    row_alpha = []
    for a, b in zip(row_from, row_to):
        strip_a, strip_b = grid[(a + 1) % n_rows], grid[b]  # (cols, L, th, tw, 3)
        err = _cut_error(strip_a[:, u], strip_b[:, u])  # (cols, th, tw)
        across = cut_alpha(err.transpose(0, 2, 1).reshape(n_cols * tw, th), fade=JUMP_FADE * th)
        alpha = across.reshape(n_cols, tw, th).transpose(0, 2, 1)
        row_alpha.append(alpha)
        cells.append(_blend(strip_a, strip_b, alpha[:, None, :, :, None]))
    for i, (ra, rb) in enumerate(zip(row_from, row_to)):
        for j, (ca, cb) in enumerate(zip(col_from, col_to)):
            top, bottom = (ra + 1) % n_rows, rb
            x_top = cells[j][top]  # the column jump strip at the two torus rows
            x_bottom = cells[j][bottom]
            ax = 0.5 * (col_alpha[j][top] + col_alpha[j][bottom])
            ay = ax * row_alpha[i][(ca + 1) % n_cols] + (1 - ax) * row_alpha[i][cb]
            cells.append(_blend(x_top[None], x_bottom[None], ay[None, None, :, :, None]))
    flat = [c.reshape(-1, length, th, tw, 3) for c in cells]
    extra = np.concatenate(flat) if flat else np.zeros((0, length, th, tw, 3), np.uint8)
    return TorusJumps(n_rows, n_cols, k, col_from, col_to, row_from, row_to, extra)


def _cut_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared RGB difference summed over frames: ``(n, L, th, tw, 3)`` pairs -> ``(n, th, tw)``."""
    d = a.astype(np.float32) - b.astype(np.float32)
    return (d * d).sum(axis=(1, 4))


def _blend(a: np.ndarray, b: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """``alpha a + (1 - alpha) b`` as uint8, ``alpha`` broadcast over frames and channels and
    taken in 256ths (integer arithmetic: the jump cells of a 4K output are ~100 MB)."""
    w = np.rint(np.asarray(alpha) * 256).astype(np.uint16)
    return ((a.astype(np.uint16) * w + b.astype(np.uint16) * (256 - w) + 128) >> 8).astype(np.uint8)
