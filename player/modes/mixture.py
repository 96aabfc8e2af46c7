"""Mode ``mixture``: real-time synthesis from a subspace-mixture dynamic texture.

Per frame the host runs the AR(p) recursion on the ``D``-dimensional global coordinate,
drawing ``draws`` noise vectors and keeping the candidate nearest the training coordinates
(the learned manifold) among those whose frame differs from the last one by no more than the
clip's own frame steps do (``STEP_QUANTILE`` of the decoded training steps; a candidate that
switches to a component decoding a different image would otherwise make the whole frame jump),
then decodes it to responsibilities ``r_s`` and local coordinates
``z_s`` (microseconds: ``S`` small Gaussians and ``d x D`` maps). The image is the
projection of ``u = (r_s, r_s z_s)`` onto the stacked basis (component means and loadings)
with the LDS mode's ``project`` kernel (:mod:`dynatex.player.engines.projection`): one launch per frame,
memory-bound on the stacked basis.

A model with switching dynamics (``model.switching``, analysed since format 1.6) is played by them
instead: the component follows the learned Markov chain, every component's local coordinates run
their own AR process (``local_ar``, order 2 as analysed; on the component's subspace, with its
covariance), and a switch cross-fades the responsibilities from the old component to the new one
over as many frames as keep each frame's step within the clip's typical one (``FADE_QUANTILE`` of
its steps), so a switch changes the frame no faster than the clip's own motion. The chain waits for a
fade to end (a component the clip holds for fewer frames than a fade lasts is still reached) and then
leaves that much sooner, so a visit lasts as long as the chain's on average and the long-run shares
stay the clip's; during a fade the components' fluctuations make up the energy that the blend of two
mean images lacks, so a fade keeps the frame's expected energy. Such a texture does not offer ``draws``.

A switching model with a ``residual`` part (:class:`~dynatex.tiledb.ResidualProcess`) adds what the
components leave out of each frame: its axes' AR processes run beside the components' (with the
``intensity``), and each frame's coefficients over the stacked rows and the part's extra rows gain
their coordinates through its ``gain``; the vector a frame is made of is then the components'
coefficients followed by the axes' coordinates.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import Range
from ...errors import InvalidArgumentError
from ...tiledb import MixtureModel
from ...tiledb.mixture import scalar_ar_autocov
from ..base import rng_from_state
from ..controls import Control
from .projected import ProjectionPlayer

DEFAULT_DRAWS = 16
MAX_DRAWS = 1024
STEP_QUANTILE = 0.99
STEP_PIXELS = 1 << 16  # pixels (basis columns) the frame-step measure averages over
MAX_FADE = 32  # frames a switch's cross-fade may last
FADE_QUANTILE = 0.5


class GlobalDecoder:
    """Decodes global coordinates to projection coefficients ``u`` (responsibilities and local coordinates).

    ``r_s(g) ~ pi_s N(g; m_s, Sigma_s)`` (the per-component Gaussians of the training global
    coordinates) and ``z_s = c_s + K_s (g - m_s)``, the conditional mean of the local
    coordinates given ``g`` under the component's joint Gaussian (stored by the analyzer),
    pulled back into the ellipsoid of the component's training coordinates (a local linear
    model is only valid near its data; far-off ``g`` would otherwise decode to huge images).
    """

    def __init__(self, model: MixtureModel) -> None:
        s, d, dg = model.components, model.dim, model.global_dim
        self.s, self.d, self.dg = s, d, dg
        self.offset = model.decode_offset.copy()  # (S, d)
        self.gain = model.decode_gain.copy()  # (S, d, D)
        self.local_whiten = np.linalg.inv(np.linalg.cholesky(model.local_cov))  # (S, d, d)
        self.radius = model.local_radius.copy()
        chol = np.linalg.cholesky(model.gauss_cov)  # (S, D, D)
        self.whiten = np.linalg.inv(chol)
        self.centre = model.gauss_mean.copy()
        self.lognorm = np.log(np.maximum(model.weights, 1e-300)) - np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(
            axis=1
        )

    def responsibilities(self, g: np.ndarray) -> np.ndarray:
        """``(N, D)`` -> ``(N, S)``."""
        e = np.einsum("sij,nsj->nsi", self.whiten, g[:, None, :] - self.centre[None])
        logp = self.lognorm[None] - 0.5 * np.einsum("nsi,nsi->ns", e, e)
        logp -= logp.max(axis=1, keepdims=True)
        p = np.exp(logp)
        return p / p.sum(axis=1, keepdims=True)

    def coefficients(self, g: np.ndarray) -> np.ndarray:
        """``(N, D)`` or ``(D,)`` global coordinates -> ``(N, S (d + 1))`` (or ``(S (d + 1),)``) coefficients."""
        g = np.asarray(g, dtype=float)
        single = g.ndim == 1
        g2 = g[None] if single else g
        r = self.responsibilities(g2)
        dz = np.einsum("sij,nsj->nsi", self.gain, g2[:, None, :] - self.centre[None])
        rad = np.sqrt((np.einsum("sij,nsj->nsi", self.local_whiten, dz) ** 2).sum(axis=2))  # (N, S)
        dz *= np.minimum(1.0, self.radius[None] / np.maximum(rad, 1e-300))[:, :, None]
        z = self.offset[None] + dz
        u = np.concatenate([np.ones(z.shape[:2] + (1,)), z], axis=2) * r[:, :, None]
        u = u.reshape(g2.shape[0], -1)
        return u[0] if single else u


def step_gram(basis: np.ndarray) -> np.ndarray:
    """``(J, J)`` Gram matrix of the basis rows over (at most ``STEP_PIXELS`` evenly spaced) columns,
    per column: ``du^T G du`` is the mean squared pixel change of a coefficient change ``du``."""
    cols = basis[:, :: max(1, basis.shape[1] // STEP_PIXELS)].astype(np.float64)
    return cols @ cols.T / cols.shape[1]


def step_sizes(gram: np.ndarray, du: np.ndarray) -> np.ndarray:
    """Mean squared pixel change of each coefficient change, rows of ``du`` (N, J) -> (N,)."""
    return ((du @ gram) * du).sum(axis=1)


def nearest_distance(train: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Euclidean distance of each row of ``g`` (N, D) to its nearest row of ``train`` (T, D)."""
    d2 = (g * g).sum(1)[:, None] - 2 * g @ train.T + (train * train).sum(1)[None]
    return np.sqrt(np.maximum(d2.min(axis=1), 0))


class MixturePlayer(ProjectionPlayer):
    """Endless frames from a texture's ``mixture`` model.

    Examples
    --------
    >>> with MixturePlayer("water.h5", seed=3) as p:     # doctest: +SKIP
    ...     p.draws = 16
    ...     frame = p.next_frame()
    """

    mode = "mixture"
    method = "mixture"
    basis_name = "stacked_basis"

    checked_first = ("precision", "draws", "lookahead")

    def _open(self, *, seed: int, precision: str, lookahead: int | None, draws: int = DEFAULT_DRAWS) -> None:
        super()._open(seed=seed, precision=precision, lookahead=lookahead)
        if self.switching is not None and draws != DEFAULT_DRAWS:
            raise InvalidArgumentError(f"this texture does not offer the control draws: {type(self).draws.unoffered}")
        self._draws = draws
        if self.residual is not None:
            self._res_hist = self._stationary_residual()

    def _setup(self, model: MixtureModel) -> None:
        src = self.texture.source
        self.components, self.dim, self.global_dim, self.order = (
            model.components,
            model.dim,
            model.global_dim,
            model.order,
        )
        self._dim = self.global_dim
        self._shape = (src.height, src.width, self.format.bytes)
        self.decoder = GlobalDecoder(model)
        self.train_coords = np.ascontiguousarray(model.global_coords)
        self._train_sq = (self.train_coords**2).sum(axis=1)
        self._A = np.ascontiguousarray(model.ar_coefs)
        self._w = model.ar_intercept.copy()
        self._noise = np.linalg.cholesky(model.ar_noise_cov)
        p = self.order
        self._gram = step_gram(model.stacked_basis)
        self._coord_map = model.coord_map
        self.switching = model.switching
        self.residual = model.residual if self.switching is not None else None
        if self.switching is not None:
            z = model.local_coords
            ext = np.concatenate([np.ones(z.shape[:2] + (1,)), z], axis=2)
            train = (ext * model.responsibilities[:, :, None]).reshape(len(z), -1)
        else:
            train = self.decoder.coefficients(self.train_coords)
        steps = step_sizes(self._gram, np.diff(train, axis=0))
        self._step_limit = float(np.quantile(steps, STEP_QUANTILE))
        self._fade_step = float(np.quantile(steps, FADE_QUANTILE))
        self._hist0 = self.train_coords[p - 1 :: -1].copy()  # hist[i] = g_{t-i}
        self._hist = self._hist0.copy()
        if self.switching is not None:
            self._dim = self.components * (self.dim + 1)
            self._offset = model.decode_offset
            self._label = int(model.responsibilities[0].argmax())
            self._stay = np.diag(self.switching.transitions).copy()
            j = self.dim + 1
            means = np.concatenate([np.ones((self.components, 1)), self._offset], axis=1)  # (S, d + 1)
            blocks = [self._gram[s * j : (s + 1) * j, s * j : (s + 1) * j] for s in range(self.components)]
            rows = np.zeros((self.components, self.components * j))
            for s in range(self.components):
                rows[s, s * j : (s + 1) * j] = means[s]
            self._mean_gram = rows @ self._gram @ rows.T  # (S, S): mean images' products, per pixel
            self._fluct = np.array([np.trace(model.local_cov[s] @ b[1:, 1:]) for s, b in enumerate(blocks)])
            order = self.switching.local_ar.shape[1]
            self._zh = np.repeat(model.local_coords[:1] - self._offset[None], order, axis=0)  # z_{t-i} - c
            self._eye = np.eye(self.components)
            self._r = self._eye[self._label].copy()
            self._fade = (self._r.copy(), 0, 0)  # responsibilities at the switch, frames done, frames in all
            self._u = self._switch_coefficients(self._r)
        if self.residual is not None:
            self._res_hist = np.zeros((self.residual.ar.shape[1], self.residual.ar.shape[0]))  # y_{t-i}
            self._dim += self.residual.ar.shape[0]

    def _stationary_residual(self) -> np.ndarray:
        """The residual axes' last ``order`` values drawn from each axis's stationary distribution, so
        the first frames carry the residual's energy as the components' training start carries theirs."""
        res = self.residual
        order = res.ar.shape[1]
        hist = np.empty((order, res.ar.shape[0]))
        for a in range(res.ar.shape[0]):
            gamma = scalar_ar_autocov(res.ar[a], order - 1) * res.noise[a] ** 2
            lam, vec = np.linalg.eigh(gamma[np.abs(np.subtract.outer(np.arange(order), np.arange(order)))])
            hist[:, a] = vec @ (np.sqrt(np.maximum(lam, 0.0)) * self._rng.standard_normal(order))
        return hist

    def _basis(self, model: MixtureModel) -> np.ndarray:
        if self.residual is None or not len(self.residual.rows):
            return model.stacked_basis
        return np.concatenate([model.stacked_basis, self.residual.rows])

    # -- controls ----------------------------------------------------------------
    draws = Control(
        Range(int, 1, MAX_DRAWS),
        DEFAULT_DRAWS,
        "Noise draws per step; the candidate nearest the learned manifold is kept among those whose frame "
        "step stays within the clip's own (1: the plain AR process). Offered only by textures analysed "
        "without switching dynamics (before format 1.6).",
        offered=lambda player: player.switching is None,
        unoffered="it has no effect on a texture with switching dynamics (analysed since format 1.6), whose "
        "process stays on the components by itself",
    )

    # -- synthesis -----------------------------------------------------------------
    @property
    def global_coord(self) -> np.ndarray:
        """The global coordinate of the next frame (a copy)."""
        self._settle()
        if self.switching is not None:
            return self._u @ self._coord_map
        return self._hist[0].copy()

    def _switch_coefficients(self, r: np.ndarray) -> np.ndarray:
        """The coefficients of the current local coordinates under responsibilities ``r``, each
        component's pulled back into the ellipsoid of its training coordinates (as
        :class:`GlobalDecoder` does; the process runs on)."""
        dz = self._zh[0]
        rad = np.sqrt((np.einsum("sij,sj->si", self.decoder.local_whiten, dz) ** 2).sum(axis=1))
        dz = dz * np.minimum(1.0, self.decoder.radius / np.maximum(rad, 1e-300))[:, None]
        # Mean images mix by the responsibilities; the components' independent fluctuations by
        # weights whose squares sum to one, so that a cross-fade keeps their variance.
        w = r / np.sqrt(r @ r)
        if r.max() < 1.0:
            # the blend of two mean images lacks sum r_s |m_s|^2 - |sum r_s m_s|^2 of the energy the
            # components hold on average: the fluctuations make it up
            lost = r @ np.diag(self._mean_gram) - r @ self._mean_gram @ r
            have = (w * w) @ self._fluct
            w = w * np.sqrt(1.0 + max(lost, 0.0) / max(have, 1e-300))
        ext = np.concatenate([r[:, None], r[:, None] * self._offset + w[:, None] * dz], axis=1)
        return ext.reshape(-1)

    def _switch_step(self) -> None:
        dyn = self.switching
        draw = self._rng.random()
        start, done, total = self._fade
        if done < total:
            new = self._label
        else:
            new = self._leave(draw, total)
        eps = self._rng.standard_normal(self._zh.shape[1:])
        dz = np.einsum("spij,psj->si", dyn.local_ar, self._zh)
        dz += np.sqrt(self._intensity) * np.einsum("sij,sj->si", dyn.local_noise, eps)
        self._zh[1:] = self._zh[:-1]
        self._zh[0] = dz
        if new != self._label:
            jump = self._switch_coefficients(self._eye[new]) - self._switch_coefficients(self._r)
            size = step_sizes(self._gram, jump[None])[0]
            total = int(min(MAX_FADE, np.ceil(np.sqrt(size / max(self._fade_step, 1e-300)))))
            start, done, self._label = self._r.copy(), 0, new
        one = self._eye[self._label].copy()
        if done < total:
            done += 1
            self._r = (1 - done / total) * start + (done / total) * one
        else:
            self._r = one
        self._fade = (start, done, total)
        self._u = self._switch_coefficients(self._r)
        if self.residual is not None:
            res, hist = self.residual, self._res_hist
            y = np.einsum("ap,pa->a", res.ar, hist) + np.sqrt(self._intensity) * res.noise * self._rng.standard_normal(
                res.noise.shape[0]
            )
            hist[1:] = hist[:-1]
            hist[0] = y

    def _leave(self, draw: float, fade: int) -> int:
        """The component after this frame, past a fade of ``fade`` frames: the chain's own choice,
        leaving more often so that a visit (fade included) lasts as long as the chain's on average."""
        i = self._label
        leave = 1.0 - self._stay[i]
        if leave <= 0.0:
            return i
        raised = leave / max(1.0 - fade * leave, leave)
        if draw >= raised:
            return i
        row = self.switching.transitions[i].copy()
        row[i] = 0.0
        cum = np.cumsum(row) / leave
        return min(int(np.searchsorted(cum, draw / raised, side="right")), self.components - 1)

    def _step(self) -> None:
        if self.switching is not None:
            self._switch_step()
            return
        pred = self._w + np.einsum("pij,pj->i", self._A, self._hist)
        eps = self._rng.standard_normal((self._draws, self.global_dim))
        cand = pred + np.sqrt(self._intensity) * (eps @ self._noise.T)
        if self._draws > 1:
            d2 = (self._train_sq[None] - 2 * cand @ self.train_coords.T).min(axis=1) + (cand * cand).sum(1)
            u0 = self._decoded(self._hist[0])
            pick = int(np.argmin(d2))
            u = self.decoder.coefficients(cand[pick])
            if step_sizes(self._gram, (u - u0)[None])[0] > self._step_limit:  # decode them all
                us = self.decoder.coefficients(cand)
                step = step_sizes(self._gram, us - u0)
                within = step <= self._step_limit
                pick = int(np.argmin(np.where(within, d2, np.inf)) if within.any() else np.argmin(step))
                u = us[pick]
            best = cand[pick]
            self._last_decoded = (best.copy(), u)
        else:
            best = cand[0]
        self._hist[1:] = self._hist[:-1]
        self._hist[0] = best

    def _vector(self) -> np.ndarray:
        """The global coordinate; with switching dynamics, the projection coefficients themselves
        (followed by the residual's axis coordinates where the model has them)."""
        if self.residual is not None:
            return np.concatenate([self._u, self._res_hist[0]])
        return self._u if self.switching is not None else self._hist[0]

    def _decoded(self, g: np.ndarray) -> np.ndarray:
        """The coefficients of ``g``, from the last step's decode when it drew ``g`` (a cache only)."""
        last = getattr(self, "_last_decoded", None)
        if last is not None and np.array_equal(last[0], g):
            return last[1]
        return self.decoder.coefficients(g)

    def _coefficients(self, v: np.ndarray, coef: np.ndarray) -> None:
        if self.residual is not None:
            j = self.components * (self.dim + 1)
            full = v[j:] @ self.residual.gain
            full[:j] += v[:j]
            coef[:] = full
            return
        coef[:] = v if self.switching is not None else self.decoder.coefficients(v)

    def render_coord(self, g: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Decode and project an arbitrary global coordinate; the player does not advance."""
        if self.switching is None:
            return self._render_vector("g", g, out)
        g = np.asarray(g, dtype=float)
        if g.shape != (self.global_dim,) or not np.isfinite(g).all():
            raise InvalidArgumentError(f"g must be a finite vector of shape ({self.global_dim},)")
        u = self.decoder.coefficients(g)
        if self.residual is not None:
            u = np.concatenate([u, np.zeros(self.residual.ar.shape[0])])
        return self._render_vector("coefficients", u, out)

    # -- state ---------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        if self.switching is not None:
            start, done, total = self._fade
            return {
                "component": self._label,
                "local": self._zh.copy(),
                "responsibilities": self._r.copy(),
                "fade_from": start.copy(),
                "fade_done": done,
                "fade_frames": total,
                **({"residual": self._res_hist.copy()} if self.residual is not None else {}),
                "rng": self._rng.bit_generator.state,
                "seed": self.seed,
                **self._detail_state(),
            }
        return {
            "history": self._hist.copy(),
            "rng": self._rng.bit_generator.state,
            "seed": self.seed,
            **self._detail_state(),
        }

    def _set_state(self, state: dict[str, Any]) -> None:
        if self.switching is not None:
            self._set_switch_state(state)
            return
        hist = np.asarray(state["history"], dtype=float)
        if hist.shape != self._hist.shape or not np.isfinite(hist).all():
            raise InvalidArgumentError(f"state history must be finite with shape {self._hist.shape}")
        rng = rng_from_state(state["rng"])
        self._restore_detail(state)
        self._hist = hist.copy()
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))

    def _set_switch_state(self, state: dict[str, Any]) -> None:
        s_count = self.components
        try:
            label = int(state["component"])
            z = np.asarray(state["local"], dtype=float)
            r = np.asarray(state["responsibilities"], dtype=float)
            start = np.asarray(state["fade_from"], dtype=float)
            done, total = int(state["fade_done"]), int(state["fade_frames"])
            res_hist = None
            if self.residual is not None:
                res_hist = np.asarray(state.get("residual", np.zeros_like(self._res_hist)), dtype=float)
        except (KeyError, TypeError, ValueError) as e:
            raise InvalidArgumentError(f"state of a switching mixture is missing or malformed: {e}") from None
        if not 0 <= label < s_count or z.shape != self._zh.shape or r.shape != (s_count,) or start.shape != (s_count,):
            raise InvalidArgumentError(
                f"state must have component in 0..{s_count - 1}, local of shape {self._zh.shape} and "
                f"responsibilities and fade_from of shape ({s_count},)"
            )
        if not (np.isfinite(z).all() and np.isfinite(r).all() and np.isfinite(start).all()) or not 0 <= done <= total:
            raise InvalidArgumentError(
                "state local, responsibilities and fade_from must be finite, with 0 <= fade_done <= fade_frames"
            )
        if res_hist is not None:
            if res_hist.shape != self._res_hist.shape or not np.isfinite(res_hist).all():
                raise InvalidArgumentError(f"state residual must be finite with shape {self._res_hist.shape}")
        rng = rng_from_state(state["rng"])
        self._restore_detail(state)
        if res_hist is not None:
            self._res_hist = res_hist.copy()
        self._label, self._zh, self._r, self._fade = label, z.copy(), r.copy(), (start.copy(), done, total)
        self._u = self._switch_coefficients(self._r)
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))
