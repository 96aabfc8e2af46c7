"""One sign convention for every SVD or eigen component the analyzer stores.

A singular or eigen vector is defined up to its sign, and each solver (LAPACK build, BLAS
threads, CPU) is free to return either. The analyzer turns every component it stores to the
side where its dot product with a fixed, pseudo-random weight vector ``w`` is positive.

Why not the usual "largest entry positive": on a symmetric input (a mirrored clip, a
symmetric test pattern) two entries tie in magnitude with opposite signs, and the last bit
of rounding picks the winner, so two machines store opposite components. The rule here
flips a component only where ``w . u`` changes sign, a hyperplane that has nothing to do
with the input's structure: ``w`` is a hash of the entry's index, so no symmetry or
periodicity of an image lines up with it. For a unit vector ``u`` of ``m`` entries,
``w . u`` is of order ``|w| / sqrt(m)`` while rounding moves it by about ``eps |w|``, so
inputs that differ in their last bits give the same signs except with probability of order
``eps * sqrt(m)`` (below 1e-3 for anything a clip produces).
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError

__all__ = ["sign_weights", "canonical_signs", "orient_rows"]

_CHUNK = 1 << 20
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


def sign_weights(start: int, stop: int) -> np.ndarray:
    """The weights ``w[start:stop]``: splitmix64 of each index, mapped to ``[-1, 1)`` (float64).

    >>> w = sign_weights(0, 5)
    >>> bool(np.all(np.abs(w) <= 1)), bool(np.array_equal(w[2:], sign_weights(2, 5)))
    (True, True)
    """
    z = np.arange(start, stop, dtype=np.uint64) * _GOLDEN + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z ^= z >> np.uint64(31)
    return (z >> np.uint64(11)).astype(np.float64) * (2.0**-52) - 1.0


def canonical_signs(rows: np.ndarray) -> np.ndarray:
    """``+1`` or ``-1`` per row of ``rows`` (a 2-D array, one component a row): the sign that
    makes the row's dot product with :func:`sign_weights` positive (``+1`` for a zero row).

    The weights are made a chunk at a time, so a basis of any size costs no extra copy.

    >>> u = np.array([[0.6, -0.8, 0.0], [-0.6, 0.8, 0.0]])
    >>> canonical_signs(u).tolist()
    [1.0, -1.0]
    """
    rows = np.asarray(rows)
    if rows.ndim != 2:
        raise InvalidArgumentError(f"rows must be a 2-D array, not shape {rows.shape}")
    dots = np.zeros(rows.shape[0], np.float64)
    for p0 in range(0, rows.shape[1], _CHUNK):
        p1 = min(p0 + _CHUNK, rows.shape[1])
        dots += rows[:, p0:p1].astype(np.float64, copy=False) @ sign_weights(p0, p1)
    return np.where(dots < 0, -1.0, 1.0)


def orient_rows(rows: np.ndarray) -> np.ndarray:
    """``rows`` with each row turned to its canonical sign (:func:`canonical_signs`); same dtype.

    >>> a = orient_rows(np.array([[0.6, -0.8]]))
    >>> bool(np.array_equal(a, orient_rows(-a)))
    True
    """
    return rows * canonical_signs(rows)[:, None].astype(rows.dtype)
