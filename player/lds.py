"""Mode ``lds``: real-time synthesis and live editing of a linear dynamic texture.

Per frame the host advances the n-dimensional state (``x <- A_s x + sqrt(intensity) B v``,
microseconds) and one OpenCL kernel projects it, ``frame = basis^T (w * x) + mean``,
straight to uint8: the only per-frame cost that grows with the frame size, memory-bound
on the basis.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..checks import Array, Numbers, Range
from ..errors import InvalidArgumentError
from ..tiledb import LDSModel
from .base import rng_from_state
from .controls import Control
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
    """Poles for playback at ``speed``: angles scaled by ``speed`` (negative reverses time),
    magnitudes kept; poles pushed past pi are annihilated (set to 0).

    Real negative poles (angle pi) have no conjugate partner to rotate with; they become
    ``|p| cos(speed * pi)``, the real part of the rotated pole.
    """
    mag = np.abs(poles)
    ang = np.angle(poles)
    neg_real = (np.abs(poles.imag) <= 1e-12 * np.maximum(mag, 1e-300)) & (poles.real < 0)
    new = mag * np.exp(1j * ang * speed)
    new = np.where(neg_real, mag * np.cos(np.pi * speed), new)
    new = np.where(np.abs(ang * speed) > np.pi + 1e-12, 0.0, new)
    return new


class LDSPlayer(ProjectionPlayer):
    """Endless frames from a texture's ``lds`` model, with live edits.

    Examples
    --------
    >>> with LDSPlayer("water.h5", seed=3) as p:     # doctest: +SKIP
    ...     p.speed = -1.0                            # play backwards
    ...     frame = p.next_frame()
    """

    mode = "lds"

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
        self._vecs_inv = np.linalg.inv(self._vecs)
        self._groups = scale_groups(self.n)
        self._weights = np.ones(self.n)
        self._A_edit = self._A
        self._w = np.ones(self.n)
        self._x = self._x0.copy()

    # -- controls ----------------------------------------------------------------
    speed = Control(Range(float, *SPEED_RANGE), 1.0, "Pole angles scaled by speed; negative plays time backwards.")

    @speed.setter
    def speed(self, value: float) -> None:
        self._speed = value
        if value == 1.0:
            self._A_edit = self._A
        else:
            poles = edited_poles(self._poles, value)
            self._A_edit = np.ascontiguousarray(((self._vecs * poles) @ self._vecs_inv).real)

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
        return self._x.copy()

    def _step(self) -> None:
        v = self._rng.standard_normal(self.k)
        self._x = self._A_edit @ self._x + np.sqrt(self._intensity) * (self._B @ v)

    def _vector(self) -> np.ndarray:
        return self._x

    def _coefficients(self, x: np.ndarray, coef: np.ndarray) -> None:
        np.multiply(self._w, x, out=coef[: self.n], casting="same_kind")

    def render_state(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Project an arbitrary state to a frame (the current weights apply); the player does not advance."""
        return self._render_vector("x", x, out)

    # -- state ---------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {"x": self._x.copy(), "rng": self._rng.bit_generator.state, "seed": self.seed}

    def _set_state(self, state: dict[str, Any]) -> None:
        x = np.asarray(state["x"], dtype=float)
        if x.shape != (self.n,) or not np.isfinite(x).all():
            raise InvalidArgumentError(f"state x must be finite with shape ({self.n},)")
        rng = rng_from_state(state["rng"])
        self._x = x.copy()
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))
