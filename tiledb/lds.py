"""The learned linear dynamical system of a texture (the ``lds`` group).

Model: ``x(t+1) = A x(t) + B v(t)``, ``v ~ N(0, I_k)``; ``frame = basis.T @ x + mean``, in
pixel values, or in tone values that the model's ``tone`` map takes back to pixels.
Everything the player needs is stored ready to use: opening a player costs at most
``n x n`` work (an eigendecomposition of ``A``), never a decomposition of the frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from . import detail as _detail
from . import gamut as _gamut
from . import tone as _tone
from ._check import Checker
from ._describe import Described
from .source import SourceInfo

#: Largest spectral radius a stored transition matrix may have.
MAX_SPECTRAL_RADIUS = 1.0 - 1e-9
#: Largest condition number of ``A``'s eigenvectors: the player inverts them to edit the poles.
MAX_EIGVEC_CONDITION = 1e10


@dataclass
class LDSModel(Described):
    """A linear dynamic texture.

    Attributes
    ----------
    mean : (P,) float32
        Mean frame, values on the 0..255 scale (in tone units with a ``tone`` map), pixels in
        ``(H, W, C)`` row-major order.
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
    detail : DetailModel, optional
        The fine detail and colour range added to the projected frames (the optional ``detail``
        subgroup, :mod:`.detail`); None in databases written without it.
    gamut : GamutModel, optional
        The source's colour set, which the projected frames are held to (the optional ``gamut``
        subgroup, :mod:`.gamut`); None in databases written without it and for grey sources.
    tone : ToneModel, optional
        The per-channel map from levels to the tone values the model was learned on (the
        required ``tone`` subgroup, :mod:`.tone`); None for a model learned on pixel values.
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
    detail: _detail.DetailModel | None = None
    gamut: _gamut.GamutModel | None = None
    tone: _tone.ToneModel | None = None

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def k(self) -> int:
        return int(self.B.shape[1])

    def describe(self) -> dict:
        """Facts as plain values: the ``info`` attributes, the orders and the basis size."""
        return {
            **super().describe(),
            "n": self.n,
            "k": self.k,
            "basis_mb": round(self.basis.nbytes / 2**20, 2),
            **_detail.describe(self.detail, self.info),
            **_gamut.describe(self.gamut),
            **_tone.describe(self.tone),
        }

    def summary(self) -> str:
        """One line: orders, energy kept, spectral radius before and after clipping."""
        info = self.info
        return (
            f"n={self.n} k={self.k}, energy {info.get('energy_captured', 0):.3f}, "
            f"spectral radius {info.get('spectral_radius_raw', 0):.4f} -> {info.get('spectral_radius', 0):.4f} "
            f"({info.get('poles_clipped', 0)} poles clipped)" + _tone.summary(self.tone)
        )


def write(group: h5py.Group, model: LDSModel) -> None:
    n = model.n
    group.create_dataset("mean", data=np.asarray(model.mean, np.float32))
    group.create_dataset("basis", data=np.asarray(model.basis, np.float32), chunks=(1, model.basis.shape[1]))
    for name in ("singular_values", "A", "B", "x0", "states", "stationary_cov"):
        group.create_dataset(name, data=np.asarray(getattr(model, name), np.float64))
    group.attrs["n"] = n
    group.attrs["k"] = model.k
    for key, value in model.info.items():
        if key not in ("n", "k"):
            group.attrs[key] = value
    _detail.write(group, model.detail)
    _gamut.write(group, model.gamut)
    _tone.write(group, model.tone)


def read(group: h5py.Group, check: Checker, source: SourceInfo) -> LDSModel:
    p = source.pixels
    n = check.attr(group, "n", int)
    k = check.attr(group, "k", int)
    if not 1 <= n <= 4096:
        check.fail(group.name + "@n", f"state order {n} out of range 1..4096")
    if not 1 <= k <= n:
        check.fail(group.name + "@k", f"noise rank {k} out of range 1..{n}")
    ds = check.dataset
    t = source.n_frames  # the SVD and the training states have at most one value or column per frame
    model = LDSModel(
        mean=ds(group, "mean", kind="f", shape=(p,)),
        basis=ds(group, "basis", kind="f", shape=(n, p)),
        singular_values=ds(group, "singular_values", kind="f", shape=(range(n, t + 1),)),
        A=ds(group, "A", kind="f", shape=(n, n)),
        B=ds(group, "B", kind="f", shape=(n, k)),
        x0=ds(group, "x0", kind="f", shape=(n,)),
        states=ds(group, "states", kind="f", shape=(n, range(1, t + 1))),
        stationary_cov=ds(group, "stationary_cov", kind="f", shape=(n, n)),
        info=check.info(group),
        detail=_detail.read(group, check, source),
        gamut=_gamut.read(group, check, source),
        tone=_tone.read(group, check, source),
    )
    _tone.check_mean(group.name + "/mean", model.mean, model.tone, check)
    _check_dynamics(group.name, model, check, p)
    return model


def _check_dynamics(path: str, model: LDSModel, check: Checker, pixels: int) -> None:
    """Reject models that cannot make frames: a basis that is not orthonormal (a zero basis), a
    transition matrix that is unstable or not diagonalisable (the player edits its poles), no
    driving noise, or states that leave the range of the frames' values.

    With orthonormal basis rows ``||frame - mean|| = ||x||``, and a frame and the mean both lie
    in the 0..255 cube, so the state of any frame has ``||x|| <= 256 sqrt(P)`` (with a tone map
    the cube of its values: ``256`` becomes :func:`.tone.value_span`). The stored
    states, the expected state ``A^t x0`` of every frame to come and the stationary spread
    ``trace(P)`` must respect that bound; beyond it the state only saturates pixels, and far
    beyond it (an ``x0`` of 1e308) it overflows to a black screen.
    """
    bound = _tone.value_span(model.tone) * np.sqrt(pixels)
    with np.errstate(all="ignore"):  # huge values overflow to inf, which every test below refuses
        _check_basis(path, model, check)
        _check_poles(path, model, check)
        _check_noise(path, model, check, bound)
        _check_states(path, model, check, bound)


def _check_basis(path: str, model: LDSModel, check: Checker) -> None:
    norms = np.sqrt(np.einsum("ij,ij->i", model.basis, model.basis, dtype=np.float64))
    if not np.abs(norms - 1).max() <= 1e-3:
        check.fail(
            path + "/basis",
            f"rows are not of unit length (norms {norms.min():.3g}..{norms.max():.3g}): the basis must be orthonormal",
        )


def _check_poles(path: str, model: LDSModel, check: Checker) -> None:
    poles, vecs = np.linalg.eig(model.A)
    rho = float(np.max(np.abs(poles)))
    if not rho < MAX_SPECTRAL_RADIUS:
        check.fail(path + "/A", f"is not stable (spectral radius {rho:.6g} >= 1)")
    cond = float(np.linalg.cond(vecs))
    if not cond < MAX_EIGVEC_CONDITION:
        check.fail(
            path + "/A",
            f"is not diagonalisable (eigenvector condition number {cond:.3g}); the player's "
            "speed edit rotates its poles",
        )


def _check_noise(path: str, model: LDSModel, check: Checker, bound: float) -> None:
    q = model.B @ model.B.T
    cov = model.stationary_cov
    if not np.trace(q) > 0:
        check.fail(path + "/B", "is zero: without driving noise the texture settles to a still image")
    scale = np.abs(cov).max()
    if not (np.abs(cov - cov.T).max() <= 1e-9 * scale and np.linalg.eigvalsh(cov).min() >= -1e-9 * np.trace(cov)):
        check.fail(path + "/stationary_cov", "is not symmetric positive semi-definite")
    if not np.trace(cov) <= bound**2:
        check.fail(
            path + "/stationary_cov",
            f"spread sqrt(trace) {np.sqrt(np.trace(cov)):.3g} exceeds the pixel range's {bound:.3g}",
        )
    resid = cov - model.A @ cov @ model.A.T - q
    if not np.abs(resid).max() <= 1e-6 * max(scale, np.abs(q).max()):
        check.fail(path + "/stationary_cov", "does not solve P = A P A^T + B B^T")


def _check_states(path: str, model: LDSModel, check: Checker, bound: float) -> None:
    norms = np.sqrt((model.states**2).sum(axis=0))
    if norms.size and not norms.max() <= bound:
        check.fail(
            path + "/states", f"a state of norm {norms.max():.3g} lies outside the pixel range (norm <= {bound:.3g})"
        )
    x = model.x0.copy()
    for t in range(max(64, 4 * model.n)):
        size = float(np.sqrt(x @ x))
        if not size <= bound:
            what = "x0 has" if t == 0 else f"the expected state A^{t} x0 has"
            check.fail(path + "/x0", f"{what} norm {size:.3g}, outside the pixel range (norm <= {bound:.3g})")
        if size < 1e-9 * bound:
            break
        x = model.A @ x
