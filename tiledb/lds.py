"""The learned linear dynamical system of a texture (the ``lds`` group).

Model: ``x(t+1) = A x(t) + B v(t)``, ``v ~ N(0, I_k)``; ``frame = basis.T @ x + mean``.
Everything the player needs is stored ready to use: opening a player costs at most
``n x n`` work (an eigendecomposition of ``A``), never a decomposition of the frames.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from ._check import Checker
from .source import SourceInfo

#: Largest spectral radius a stored transition matrix may have.
MAX_SPECTRAL_RADIUS = 1.0 - 1e-9


@dataclass
class LDSModel:
    """A linear dynamic texture.

    Attributes
    ----------
    mean : (P,) float32
        Mean frame, values on the 0..255 scale, pixels in ``(H, W, C)`` row-major order.
    basis : (n, P) float32
        Orthonormal rows: the first ``n`` principal components (the columns of ``C``).
    singular_values : (r,) float64
        Every singular value the analysis computed, descending (``r >= n``).
    A : (n, n) float64
        Stable state transition matrix (spectral radius < 1).
    B : (n, k) float64
        Noise input, ``Q = B @ B.T`` (already normalised by ``1/sqrt(tau - 1)``).
    x0 : (n,) float64
        Initial state (the state of the first training frame).
    states : (n, tau) float64
        Training states, for initial conditions and checks.
    stationary_cov : (n, n) float64
        Stationary state covariance ``P = A P A.T + Q`` of the stored model.
    info : dict
        Scalars describing the fit (``n``, ``k``, ``spectral_radius_raw``, ...), stored as attributes.
    """

    mean: np.ndarray
    basis: np.ndarray
    singular_values: np.ndarray
    A: np.ndarray
    B: np.ndarray
    x0: np.ndarray
    states: np.ndarray
    stationary_cov: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def k(self) -> int:
        return int(self.B.shape[1])


def write(group: h5py.Group, model: LDSModel) -> None:
    n = model.n
    group.create_dataset("mean", data=np.asarray(model.mean, np.float32))
    group.create_dataset("basis", data=np.asarray(model.basis, np.float32),
                         chunks=(1, model.basis.shape[1]))
    for name in ("singular_values", "A", "B", "x0", "states", "stationary_cov"):
        group.create_dataset(name, data=np.asarray(getattr(model, name), np.float64))
    group.attrs["n"] = n
    group.attrs["k"] = model.k
    for key, value in model.info.items():
        if key not in ("n", "k"):
            group.attrs[key] = value


def read(group: h5py.Group, check: Checker, source: SourceInfo) -> LDSModel:
    p = source.pixels
    n = check.attr(group, "n", int)
    k = check.attr(group, "k", int)
    if not 1 <= n <= 4096:
        check.fail(group.name + "@n", f"state order {n} out of range 1..4096")
    if not 1 <= k <= n:
        check.fail(group.name + "@k", f"noise rank {k} out of range 1..{n}")
    ds = check.dataset
    model = LDSModel(
        mean=ds(group, "mean", kind="f", shape=(p,)),
        basis=ds(group, "basis", kind="f", shape=(n, p)),
        singular_values=ds(group, "singular_values", kind="f", shape=(None,)),
        A=ds(group, "A", kind="f", shape=(n, n)),
        B=ds(group, "B", kind="f", shape=(n, k)),
        x0=ds(group, "x0", kind="f", shape=(n,)),
        states=ds(group, "states", kind="f", shape=(n, None)),
        stationary_cov=ds(group, "stationary_cov", kind="f", shape=(n, n)),
        info=check.info(group),
    )
    if model.singular_values.shape[0] < n:
        check.fail(group.name + "/singular_values", f"holds {model.singular_values.shape[0]} values, fewer than n={n}")
    rho = float(np.max(np.abs(np.linalg.eigvals(model.A))))
    if not rho < MAX_SPECTRAL_RADIUS:
        check.fail(group.name + "/A", f"is not stable (spectral radius {rho:.6g} >= 1)")
    if model.mean.min() < -1 or model.mean.max() > 256:
        check.fail(group.name + "/mean", "values outside the 0..255 pixel range")
    return model
