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

The player holds one process (:class:`GlobalProcess` or :class:`SwitchingProcess`: each steps,
gives its vector and coefficients, and saves and checks its part of the state) and, beside a
switching one, the residual's axes (:class:`ResidualAxes`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...checks import Range
from ...errors import InvalidArgumentError
from ...tiledb import MixtureModel, ResidualProcess
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


class GlobalProcess:
    """The AR(p) recursion on the global coordinate with the nearest of ``draws`` candidates kept
    (module docstring): how a texture analysed before format 1.6 plays. Its vector is the global
    coordinate, decoded to coefficients per frame."""

    offers_draws = True

    def __init__(self, model: MixtureModel, decoder: GlobalDecoder, gram: np.ndarray) -> None:
        self.decoder, self.gram, self.order = decoder, gram, model.order
        self.train = np.ascontiguousarray(model.global_coords)
        self._train_sq = (self.train**2).sum(axis=1)
        self.ar = np.ascontiguousarray(model.ar_coefs)
        self.intercept = model.ar_intercept.copy()
        self.noise = np.linalg.cholesky(model.ar_noise_cov)
        steps = step_sizes(gram, np.diff(decoder.coefficients(self.train), axis=0))
        self.step_limit = float(np.quantile(steps, STEP_QUANTILE))
        self.dim = model.global_dim
        self.hist = self.train[self.order - 1 :: -1].copy()  # hist[i] = g_{t-i}
        self._last_decoded: tuple[np.ndarray, np.ndarray] | None = None

    def step(self, rng: np.random.Generator, intensity: float, draws: int) -> None:
        pred = self.intercept + np.einsum("pij,pj->i", self.ar, self.hist)
        eps = rng.standard_normal((draws, self.dim))
        cand = pred + np.sqrt(intensity) * (eps @ self.noise.T)
        if draws > 1:
            d2 = (self._train_sq[None] - 2 * cand @ self.train.T).min(axis=1) + (cand * cand).sum(1)
            u0 = self._decoded(self.hist[0])
            pick = int(np.argmin(d2))
            u = self.decoder.coefficients(cand[pick])
            if step_sizes(self.gram, (u - u0)[None])[0] > self.step_limit:  # decode them all
                us = self.decoder.coefficients(cand)
                step = step_sizes(self.gram, us - u0)
                within = step <= self.step_limit
                pick = int(np.argmin(np.where(within, d2, np.inf)) if within.any() else np.argmin(step))
                u = us[pick]
            best = cand[pick]
            self._last_decoded = (best.copy(), u)
        else:
            best = cand[0]
        self.hist[1:] = self.hist[:-1]
        self.hist[0] = best

    def _decoded(self, g: np.ndarray) -> np.ndarray:
        """The coefficients of ``g``, from the last step's decode when it drew ``g`` (a cache only)."""
        last = self._last_decoded
        if last is not None and np.array_equal(last[0], g):
            return last[1]
        return self.decoder.coefficients(g)

    def vector(self) -> np.ndarray:
        return self.hist[0]

    def coefficients(self, v: np.ndarray) -> np.ndarray:
        return self.decoder.coefficients(v)

    def global_coord(self) -> np.ndarray:
        return self.hist[0].copy()

    def state(self) -> dict[str, Any]:
        return {"history": self.hist.copy()}

    def checked_state(self, state: dict[str, Any]) -> dict[str, Any]:
        """``state``'s part of this process, checked (a one-line error where malformed)."""
        hist = np.asarray(state["history"], dtype=float)
        if hist.shape != self.hist.shape or not np.isfinite(hist).all():
            raise InvalidArgumentError(f"state history must be finite with shape {self.hist.shape}")
        return {"history": hist}

    def restore(self, checked: dict[str, Any]) -> None:
        self.hist = checked["history"].copy()


class SwitchingProcess:
    """The learned Markov chain over the components, each component's local coordinates an AR
    process, and cross-fades at a switch (module docstring): how a texture analysed since format
    1.6 plays. Its vector is the projection coefficients themselves."""

    offers_draws = False

    def __init__(self, model: MixtureModel, decoder: GlobalDecoder, gram: np.ndarray) -> None:
        self.decoder, self.gram, self.dyn = decoder, gram, model.switching
        self.components, d = model.components, model.dim
        self.coord_map = model.coord_map
        self.offset = model.decode_offset
        j = d + 1
        self.dim = self.components * j
        z = model.local_coords
        ext = np.concatenate([np.ones(z.shape[:2] + (1,)), z], axis=2)
        train = (ext * model.responsibilities[:, :, None]).reshape(len(z), -1)
        self.fade_step = float(np.quantile(step_sizes(gram, np.diff(train, axis=0)), FADE_QUANTILE))
        self.stay = np.diag(self.dyn.transitions).copy()
        means = np.concatenate([np.ones((self.components, 1)), self.offset], axis=1)  # (S, d + 1)
        blocks = [gram[s * j : (s + 1) * j, s * j : (s + 1) * j] for s in range(self.components)]
        rows = np.zeros((self.components, self.dim))
        for s in range(self.components):
            rows[s, s * j : (s + 1) * j] = means[s]
        self.mean_gram = rows @ gram @ rows.T  # (S, S): mean images' products, per pixel
        self.fluct = np.array([np.trace(model.local_cov[s] @ b[1:, 1:]) for s, b in enumerate(blocks)])
        self.eye = np.eye(self.components)
        self.label = int(model.responsibilities[0].argmax())
        self.zh = np.repeat(z[:1] - self.offset[None], self.dyn.local_ar.shape[1], axis=0)  # z_{t-i} - c
        self.r = self.eye[self.label].copy()
        self.fade = (self.r.copy(), 0, 0)  # responsibilities at the switch, frames done, frames in all
        self.u = self._coefficients_under(self.r)

    def _coefficients_under(self, r: np.ndarray) -> np.ndarray:
        """The coefficients of the current local coordinates under responsibilities ``r``, each
        component's pulled back into the ellipsoid of its training coordinates (as
        :class:`GlobalDecoder` does; the process runs on)."""
        dz = self.zh[0]
        rad = np.sqrt((np.einsum("sij,sj->si", self.decoder.local_whiten, dz) ** 2).sum(axis=1))
        dz = dz * np.minimum(1.0, self.decoder.radius / np.maximum(rad, 1e-300))[:, None]
        # Mean images mix by the responsibilities; the components' independent fluctuations by
        # weights whose squares sum to one, so that a cross-fade keeps their variance.
        w = r / np.sqrt(r @ r)
        if r.max() < 1.0:
            # the blend of two mean images lacks sum r_s |m_s|^2 - |sum r_s m_s|^2 of the energy the
            # components hold on average: the fluctuations make it up
            lost = r @ np.diag(self.mean_gram) - r @ self.mean_gram @ r
            have = (w * w) @ self.fluct
            w = w * np.sqrt(1.0 + max(lost, 0.0) / max(have, 1e-300))
        ext = np.concatenate([r[:, None], r[:, None] * self.offset + w[:, None] * dz], axis=1)
        return ext.reshape(-1)

    def step(self, rng: np.random.Generator, intensity: float, draws: int) -> None:
        dyn = self.dyn
        draw = rng.random()
        start, done, total = self.fade
        new = self.label if done < total else self._leave(draw, total)
        eps = rng.standard_normal(self.zh.shape[1:])
        dz = np.einsum("spij,psj->si", dyn.local_ar, self.zh)
        dz += np.sqrt(intensity) * np.einsum("sij,sj->si", dyn.local_noise, eps)
        self.zh[1:] = self.zh[:-1]
        self.zh[0] = dz
        if new != self.label:
            jump = self._coefficients_under(self.eye[new]) - self._coefficients_under(self.r)
            size = step_sizes(self.gram, jump[None])[0]
            total = int(min(MAX_FADE, np.ceil(np.sqrt(size / max(self.fade_step, 1e-300)))))
            start, done, self.label = self.r.copy(), 0, new
        one = self.eye[self.label].copy()
        if done < total:
            done += 1
            self.r = (1 - done / total) * start + (done / total) * one
        else:
            self.r = one
        self.fade = (start, done, total)
        self.u = self._coefficients_under(self.r)

    def _leave(self, draw: float, fade: int) -> int:
        """The component after this frame, past a fade of ``fade`` frames: the chain's own choice,
        leaving more often so that a visit (fade included) lasts as long as the chain's on average."""
        i = self.label
        leave = 1.0 - self.stay[i]
        if leave <= 0.0:
            return i
        raised = leave / max(1.0 - fade * leave, leave)
        if draw >= raised:
            return i
        row = self.dyn.transitions[i].copy()
        row[i] = 0.0
        cum = np.cumsum(row) / leave
        return min(int(np.searchsorted(cum, draw / raised, side="right")), self.components - 1)

    def vector(self) -> np.ndarray:
        return self.u

    def coefficients(self, v: np.ndarray) -> np.ndarray:
        return v

    def global_coord(self) -> np.ndarray:
        return self.u @ self.coord_map

    def state(self) -> dict[str, Any]:
        start, done, total = self.fade
        return {
            "component": self.label,
            "local": self.zh.copy(),
            "responsibilities": self.r.copy(),
            "fade_from": start.copy(),
            "fade_done": done,
            "fade_frames": total,
        }

    def checked_state(self, state: dict[str, Any]) -> dict[str, Any]:
        """``state``'s part of this process, checked (a one-line error where malformed)."""
        s_count = self.components
        try:
            label = int(state["component"])
            z = np.asarray(state["local"], dtype=float)
            r = np.asarray(state["responsibilities"], dtype=float)
            start = np.asarray(state["fade_from"], dtype=float)
            done, total = int(state["fade_done"]), int(state["fade_frames"])
        except (KeyError, TypeError, ValueError) as e:
            raise InvalidArgumentError(f"state of a switching mixture is missing or malformed: {e}") from None
        if not 0 <= label < s_count or z.shape != self.zh.shape or r.shape != (s_count,) or start.shape != (s_count,):
            raise InvalidArgumentError(
                f"state must have component in 0..{s_count - 1}, local of shape {self.zh.shape} and "
                f"responsibilities and fade_from of shape ({s_count},)"
            )
        if not (np.isfinite(z).all() and np.isfinite(r).all() and np.isfinite(start).all()) or not 0 <= done <= total:
            raise InvalidArgumentError(
                "state local, responsibilities and fade_from must be finite, with 0 <= fade_done <= fade_frames"
            )
        return {"label": label, "local": z, "r": r, "fade": (start, done, total)}

    def restore(self, checked: dict[str, Any]) -> None:
        start, done, total = checked["fade"]
        self.label, self.zh, self.r = checked["label"], checked["local"].copy(), checked["r"].copy()
        self.fade = (start.copy(), done, total)
        self.u = self._coefficients_under(self.r)


class ResidualAxes:
    """The residual part's axes played (:class:`~dynatex.tiledb.ResidualProcess`): each an AR
    process of its own, beside a switching process; its vector is the axes' coordinates, which
    reach every coefficient through the part's ``gain``. It keeps the part's processes, not its
    rows (the projection engine holds those)."""

    def __init__(self, residual: ResidualProcess) -> None:
        self.gain, self.ar, self.noise = residual.gain, residual.ar, residual.noise
        self.dim, order = residual.ar.shape
        self.hist = np.zeros((order, self.dim))  # y_{t-i}

    def start(self, rng: np.random.Generator) -> None:
        """The axes' last ``order`` values drawn from each axis's stationary distribution, so the
        first frames carry the residual's energy as the components' training start carries theirs."""
        self.hist = self.stationary(rng)

    def stationary(self, rng: np.random.Generator) -> np.ndarray:
        """One draw of the axes' last ``order`` values from their stationary distribution."""
        order = self.ar.shape[1]
        hist = np.empty((order, self.dim))
        for a in range(self.dim):
            gamma = scalar_ar_autocov(self.ar[a], order - 1) * self.noise[a] ** 2
            lam, vec = np.linalg.eigh(gamma[np.abs(np.subtract.outer(np.arange(order), np.arange(order)))])
            hist[:, a] = vec @ (np.sqrt(np.maximum(lam, 0.0)) * rng.standard_normal(order))
        return hist

    def step(self, rng: np.random.Generator, intensity: float) -> None:
        hist = self.hist
        y = np.einsum("ap,pa->a", self.ar, hist) + np.sqrt(intensity) * self.noise * rng.standard_normal(self.dim)
        hist[1:] = hist[:-1]
        hist[0] = y

    def coefficients(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The coefficients over the stacked rows and the part's extra rows of components'
        coefficients ``u`` and axis coordinates ``y``."""
        full = y @ self.gain
        full[: len(u)] += u
        return full

    def checked_state(self, state: dict[str, Any]) -> np.ndarray:
        """``state``'s residual history, checked (a state saved before the part: zeros)."""
        try:
            hist = np.asarray(state.get("residual", np.zeros_like(self.hist)), dtype=float)
        except (TypeError, ValueError) as e:
            raise InvalidArgumentError(f"state of a switching mixture is missing or malformed: {e}") from None
        if hist.shape != self.hist.shape or not np.isfinite(hist).all():
            raise InvalidArgumentError(f"state residual must be finite with shape {self.hist.shape}")
        return hist


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

    checked_first = ("precision", "draws", "lookahead", "colours")

    def _open(
        self, *, seed: int, precision: str, lookahead: int | None, colours: str, draws: int = DEFAULT_DRAWS
    ) -> None:
        super()._open(seed=seed, precision=precision, lookahead=lookahead, colours=colours)
        if not self.process.offers_draws and draws != DEFAULT_DRAWS:
            raise InvalidArgumentError(f"this texture does not offer the control draws: {type(self).draws.unoffered}")
        self._draws = draws
        if self.residual is not None:
            self.residual.start(self._rng)

    def _setup(self, model: MixtureModel) -> None:
        src = self.texture.source
        self.components, self.dim, self.global_dim, self.order = (
            model.components,
            model.dim,
            model.global_dim,
            model.order,
        )
        self._shape = (src.height, src.width, self.format.bytes)
        self.decoder = GlobalDecoder(model)
        self.train_coords = np.ascontiguousarray(model.global_coords)
        self.switching = model.switching
        gram = step_gram(model.stacked_basis)
        #: the process the frames follow: the switching dynamics where the model has them
        self.process: GlobalProcess | SwitchingProcess = (
            GlobalProcess(model, self.decoder, gram)
            if model.switching is None
            else SwitchingProcess(model, self.decoder, gram)
        )
        #: the residual's axes, played beside a switching process (None: the model has no residual part)
        self.residual = None
        if model.switching is not None and model.residual is not None:
            self.residual = ResidualAxes(model.residual)
        self._dim = self.process.dim + (self.residual.dim if self.residual is not None else 0)

    def _basis(self, model: MixtureModel) -> tuple[np.ndarray, ...]:
        if self.residual is None or not len(model.residual.rows):
            return (model.stacked_basis,)
        return (model.stacked_basis, model.residual.rows)

    # -- controls ----------------------------------------------------------------
    draws = Control(
        Range(int, 1, MAX_DRAWS),
        DEFAULT_DRAWS,
        "Noise draws per step; the candidate nearest the learned manifold is kept among those whose frame "
        "step stays within the clip's own (1: the plain AR process). Offered only by textures analysed "
        "without switching dynamics (before format 1.6).",
        offered=lambda player: player.process.offers_draws,
        unoffered="it has no effect on a texture with switching dynamics (analysed since format 1.6), whose "
        "process stays on the components by itself",
    )

    # -- synthesis -----------------------------------------------------------------
    @property
    def global_coord(self) -> np.ndarray:
        """The global coordinate of the next frame (a copy)."""
        self._settle()
        return self.process.global_coord()

    def _step(self) -> None:
        self.process.step(self._rng, self._intensity, self._draws)
        if self.residual is not None:
            self.residual.step(self._rng, self._intensity)

    def _vector(self) -> np.ndarray:
        """The process's vector (the global coordinate; with switching dynamics, the projection
        coefficients), followed by the residual's axis coordinates where the model has them."""
        if self.residual is not None:
            return np.concatenate([self.process.vector(), self.residual.hist[0]])
        return self.process.vector()

    def _coefficients(self, v: np.ndarray, coef: np.ndarray) -> None:
        if self.residual is not None:
            j = self.process.dim
            coef[:] = self.residual.coefficients(self.process.coefficients(v[:j]), v[j:])
            return
        coef[:] = self.process.coefficients(v)

    def render_coord(self, g: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Decode and project an arbitrary global coordinate; the player does not advance."""
        if isinstance(self.process, GlobalProcess):
            return self._render_vector("g", g, out)
        g = np.asarray(g, dtype=float)
        if g.shape != (self.global_dim,) or not np.isfinite(g).all():
            raise InvalidArgumentError(f"g must be a finite vector of shape ({self.global_dim},)")
        u = self.decoder.coefficients(g)
        if self.residual is not None:
            u = np.concatenate([u, np.zeros(self.residual.dim)])
        return self._render_vector("coefficients", u, out)

    # -- state ---------------------------------------------------------------------
    def _get_state(self) -> dict[str, Any]:
        return {
            **self.process.state(),
            **({"residual": self.residual.hist.copy()} if self.residual is not None else {}),
            "rng": self._rng.bit_generator.state,
            "seed": self.seed,
            **self._detail_state(),
        }

    def _set_state(self, state: dict[str, Any]) -> None:
        checked = self.process.checked_state(state)
        res_hist = self.residual.checked_state(state) if self.residual is not None else None
        rng = rng_from_state(state["rng"])
        self._restore_detail(state)
        self.process.restore(checked)
        if res_hist is not None:
            self.residual.hist = res_hist.copy()
        self._rng = rng
        self.seed = int(state.get("seed", self.seed))
