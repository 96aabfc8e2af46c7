"""Compare two learned subspace models up to what is mathematically free.

Two code paths (in memory and streamed, two BLAS builds, two CPUs) compute the same SVD with
different rounding. What they must agree on is the subspace of each group of equal singular
values, not the individual vectors inside a group, and not a sign the rule could not fix. The
analyzer's sign rule (``analyzer.signs``) makes the signs the same in practice; this module
checks the models without relying on it, so a test states the contract, not one machine's
rounding.
"""

from __future__ import annotations

import numpy as np

# float32 sums perturb a Gram matrix by about this fraction of its largest eigenvalue.
GRAM_EPS = 1e-6


def groups(sv: np.ndarray, tol: float) -> list[np.ndarray]:
    """Indices of components that rounding may mix: by Davis-Kahan a vector whose eigenvalue
    (``sv**2``) is ``gap`` from its neighbour's turns by about ``GRAM_EPS * sv[0]**2 / gap``;
    components closer than ``GRAM_EPS * sv[0]**2 / tol`` are one group."""
    ev = np.asarray(sv, np.float64) ** 2
    close = np.abs(np.diff(ev)) < GRAM_EPS * ev[0] / tol
    cuts = np.flatnonzero(~close) + 1
    return np.split(np.arange(len(ev)), cuts)


def alignment(a_rows: np.ndarray, b_rows: np.ndarray, sv: np.ndarray, tol: float) -> np.ndarray:
    """The orthogonal map ``R`` with ``a_rows ~ R @ b_rows``, block-diagonal over :func:`groups`.

    Asserts that ``R`` is orthogonal (the two row spaces are the same) and that it mixes no
    components outside a group.
    """
    a = np.asarray(a_rows, np.float64)
    b = np.asarray(b_rows, np.float64)
    r = a @ b.T
    n = r.shape[0]
    np.testing.assert_allclose(r @ r.T, np.eye(n), atol=10 * tol, err_msg="the two bases span different subspaces")
    allowed = np.zeros((n, n), bool)
    for g in groups(sv[:n], tol):
        allowed[np.ix_(g, g)] = True
    stray = np.abs(np.where(allowed, 0.0, r)).max(initial=0.0)
    assert stray < 10 * tol, f"components of distinct singular values are mixed ({stray:.2e})"
    return r


def assert_same_lds(a, b, tol: float = 1e-4) -> None:
    """Two LDS models equal up to a rotation inside groups of equal singular values (signs included)."""
    n = a.basis.shape[0]
    assert b.basis.shape == a.basis.shape
    np.testing.assert_allclose(a.singular_values[:n], b.singular_values[:n], rtol=10 * tol)
    r = alignment(a.basis, b.basis, b.singular_values, tol)
    np.testing.assert_allclose(a.basis, r @ b.basis, atol=tol * np.abs(b.basis).max())
    np.testing.assert_allclose(a.states, r @ b.states, atol=tol * np.abs(b.states).max())
    np.testing.assert_allclose(a.A, r @ b.A @ r.T, atol=tol)
    bb_a, bb_b = a.B @ a.B.T, r @ b.B @ b.B.T @ r.T
    np.testing.assert_allclose(bb_a, bb_b, atol=tol * np.abs(bb_b).max())
