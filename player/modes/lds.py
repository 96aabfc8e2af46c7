"""Mode ``lds``: real-time synthesis and live editing of a linear dynamic texture.

Per frame the host advances the n-dimensional state (``x <- A_s x + sqrt(intensity) B v``,
microseconds) and one OpenCL kernel projects it, ``frame = basis^T (w * x) + mean``,
straight to uint8: the only per-frame cost that grows with the frame size, memory-bound
on the basis.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import Array, Numbers, Range
from ...errors import InvalidArgumentError
from ...tiledb import LDSModel
from ..base import rng_from_state
from ..controls import Control
from .projected import ProjectionPlayer

MAX_WEIGHT = 10.0
SPEED_RANGE = (-3.0, 3.0)


def scale_groups(n: int) -> np.ndarray:
    """Group of each component: 0 coarse, 1 medium, 2 fine (the seed's 5/10/35 split of n=50)."""
    c = max(1, int(round(0.1 * n)))
    m = max(c + 1, int(round(0.3 * n))) if n > 2 else min(n, c + 1)
    groups = np.full(n, 2, np.int8)
    groups[:m] = 1
    groups[:c] = 0
    return groups


def edited_poles(poles: np.ndarray, speed: float) -> np.ndarray:
    """Poles of the process played ``|speed|`` times faster: ``p ** |speed|`` on the principal
    branch (magnitude ``|p| ** |speed|``, angle ``|speed| * angle(p)``).

    A conjugate pair stays conjugate. A real negative pole (angle pi) has no partner to rotate
    with; as a real matrix it becomes the real part of its power, ``|p| ** s cos(s pi)``. A
    pole at 0 stays 0 (speed 0 gives 1 for every other pole: the process stands still). The
    sign of ``speed`` is ignored here: time reversal is a change of basis, see
    :func:`speed_dynamics`.
    """
    s = abs(float(speed))
    mag = np.abs(poles)
    alive = mag > 0
    logmag = np.log(np.where(alive, mag, 1.0))
    new = np.where(alive, np.exp(s * logmag + 1j * s * np.angle(poles)), 0.0)
    if s == 0:
        new = np.where(alive, 1.0 + 0j, 0.0)
    return new


def speed_dynamics(
    a: np.ndarray, cov: np.ndarray, speed: float, eig: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Transition matrix and noise input ``(A_s, B_s)`` of the process ``x(t+1) = A x(t) + w(t)``
    (stationary covariance ``cov`` = P) played ``speed`` times faster.

    ``A_s = V diag(p ** |s|) V^-1`` (:func:`edited_poles`; the matrix power ``A ** |s|``), and the
    driving noise is re-derived so that the stationary covariance stays P:
    ``B_s B_s^T = P - A_s P A_s^T`` (eigenvalues below 0, numerical, are clipped to 0). A negative
    speed plays the time-reversed process, whose transition is ``P A_|s|^T P^-1`` (a stationary
    Gaussian process run backwards has the lag covariances transposed) with the same P. Speed 0:
    ``A_s = I``, ``B_s = 0``, the state stands still.
    """
    n = a.shape[0]
    if speed == 0:
        return np.eye(n), np.zeros((n, 0))
    poles, vecs = np.linalg.eig(a) if eig is None else eig
    a_s = np.real((vecs * edited_poles(poles, speed)) @ np.linalg.inv(vecs))
    if speed < 0:
        pinv = np.linalg.pinv(cov, hermitian=True)
        a_s = cov @ a_s.T @ pinv
    q = cov - a_s @ cov @ a_s.T
    lam, u = np.linalg.eigh(0.5 * (q + q.T))
    keep = lam > 1e-12 * max(float(lam.max(initial=0.0)), 1e-300)
    b_s = u[:, keep] * np.sqrt(lam[keep])
    return np.ascontiguousarray(a_s), np.ascontiguousarray(b_s)


class LDSPlayer(ProjectionPlayer):
    """Endless frames from a texture's ``lds`` model, with live edits.

    Examples
    --------
    >>> with LDSPlayer("water.h5", seed=3) as p:     # doctest: +SKIP
    ...     p.speed = -1.0                            # play backwards
    ...     frame = p.next_frame()
    """

    mode = "lds"
    method = "lds"

    def _setup(self, model: LDSModel) -> None:
        src = self.texture.source
        self.n, self.k = model.n, model.k
        self._dim = self.n
        self._shape = (src.height, src.width, self.format.bytes)
        self._A = model.A.copy()
        self._B = model.B.copy()
        self._x0 = model.x0.copy()
        self.stationary_cov = model.stationary_cov
        self._poles, self._vecs = np.linalg.eig(self._A)
        self._groups = scale_groups(self.n)
        self._weights = np.ones(self.n)
        self._A_edit, self._B_edit = self._A, self._B
        self._w = np.ones(self.n)
        self._x = self._x0.copy()

    # -- controls ----------------------------------------------------------------
    speed = Control(
        Range(float, *SPEED_RANGE),
        1.0,
        "Time runs speed times faster: poles p -> p^|speed|, driving noise re-derived so the stationary "
        "covariance stays the model's; 0 freezes the state, negative plays the time-reversed process.",
    )

    @speed.setter
    def speed(self, value: float) -> None:
        self._speed = value
        if value == 1.0:
            self._A_edit, self._B_edit = self._A, self._B
        else:
            self._A_edit, self._B_edit = speed_dynamics(
                self._A, self.stationary_cov, value, eig=(self._poles, self._vecs)
            )

    scales = Control(
        Numbers(Range(float, 0.0, MAX_WEIGHT), 3, "C,M,F"),
        (1.0, 1.0, 1.0),
        "Weights of the coarse, medium and fine groups of components.",
    )

    @scales.setter
    def scales(self, value: tuple[float, float, float]) -> None:
        self._scales = value
        self._update_w()

    weights = Control(
        Array(0.0, MAX_WEIGHT, ndim=1),
        None,
        "Per-component weights, multiplied with scales.",
        flag=None,
        default_doc="all 1",
    )

    @weights.setter
    def weights(self, value: np.ndarray) -> None:
        if value.shape != (self.n,):
            raise InvalidArgumentError(f"weights must have shape ({self.n},), not {value.shape}")
        self._weights = value
        self._update_w()

    def _update_w(self) -> None:
        self._w = np.asarray(self._scales)[self._groups] * self._weights

    @property
    def groups(self) -> np.ndarray:
        """Scale group of each component (0 coarse, 1 medium, 2 fine)."""
        return self._groups.copy()

    # -- synthesis -----------------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """The current state vector ``x`` (a copy)."""
        self._settle()
        return self._x.copy()

    def _step(self) -> None:
        v = self._rng.standard_normal(self._B_edit.shape[1])
        self._x = self._A_edit @ self._x + np.sqrt(self._intensity) * (self._B_edit @ v)

    def _vector(self) -> np.ndarray:
        return self._x

    def _coefficients(self, x: np.ndarray, coef: np.ndarray) -> None:
        np.multiply(self._w, x, out=coef[: self.n], casting="same_kind")

    def render_state(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Project an arbitrary state to a frame (the current weights apply); the player does not advance."""
        return self._render_vector("x", x, out)

    # -- state ---------------------------------------------------------------------
    def _detail_rate(self) -> float:
        return self._speed

    def _get_state(self) -> dict[str, Any]:
        return {"x": self._x.copy(), "rng": self._rng.bit_generator.state, "seed": self.seed, **self._detail_state()}

    def _set_state(self, state: dict[str, Any]) -> None:
        x = np.asarray(state["x"], dtype=float)
        if x.shape != (self.n,) or not np.isfinite(x).all():
            raise InvalidArgumentError(f"state x must be finite with shape ({self.n},)")
        rng = rng_from_state(state["rng"])
        self._restore_detail(state)
        self._x = x.copy()
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))
