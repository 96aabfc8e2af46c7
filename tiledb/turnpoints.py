"""Turn points and transitions of a video texture (the ``turnpoints`` group).

The player plays the stored source frames (the texture's ``frames`` dataset) in a
stochastic order: it reverses at turn points (symmetric frames) and jumps along classic
video-texture transitions. Everything it needs is stored here ready to use; the full
frame-distance matrix is not (it is ``T x T``), only the symmetry curve and the kept,
sparse transitions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import h5py
import numpy as np

from ._check import Checker
from ._describe import Described
from ._parts import exact_dtype, open_part, write_part
from .source import SourceInfo

_PER_FRAME = ("sym_raw", "symmetry", "reduced", "p_max")
_PER_TRANSITION = ("cost", "future_cost", "prob")

#: Version of the optional ``flow`` part this reader understands; a newer part is ignored.
FLOW_VERSION = 1
FLOW_GROUP = "flow"
#: Flow vectors are stored in 1 / 2**FLOW_FRACTION_BITS pixels (int16).
FLOW_FRACTION_BITS = 4
#: Largest flow grid step, in pixels (a power of two).
MAX_FLOW_STEP = 64


def flow_grid(height: int, width: int, step: int) -> tuple[int, int]:
    """Rows and columns of a flow grid with samples every ``step`` pixels from pixel 0, one beyond the last
    pixel so that bilinear interpolation of every pixel finds its four samples.

    >>> flow_grid(240, 240, 4)
    (61, 61)
    """
    return (height - 1) // step + 2, (width - 1) // step + 2


@dataclass
class FlowModel:
    """Optical flow between the frame pairs a jump's crossfade blends (motion-compensated jumps).

    Attributes
    ----------
    pairs : (P, 2) int32
        Frame pairs ``(a, b)``, ``a != b``, each once (in either order).
    flows : (P, Gh, Gw, 2) int16
        Per pair the midpoint flow ``f`` (x, y) in ``1 / 16`` pixels at grid samples every ``step``
        pixels (:func:`flow_grid`): ``a(p - f / 2)`` matches ``b(p + f / 2)``.
    step : int
        Grid step in pixels, a power of two up to :data:`MAX_FLOW_STEP`.
    """

    pairs: np.ndarray
    flows: np.ndarray
    step: int


@dataclass
class TurnPointModel(Described):
    """Turn-point and transition tables of one clip of ``T`` frames.

    Attributes
    ----------
    sym_raw : (T,) float64
        Binomially weighted mirrored distances (the seed's eq. 2); 0 where no window fits.
    symmetry : (T,) float64
        Normalised symmetry in [0, 1] (eq. 3); 0 where no window fits.
    reduced : (T,) float64
        ``symmetry`` kept only at local maxima within the range ``r`` (eq. 4), else 0.
    turn_points : (K,) int32
        Increasing frame indices of the turn points, ``K >= 2``; the first and last are the
        outermost turns, where playback always reverses when heading outward.
    p_max : (T,) float64
        Largest reversal probability per frame (eq. 5): ``reduced / 2``, 1 at the outermost turns.
    src, dst : (M,) int32
        Transitions ``src -> dst``: after showing frame ``src`` (playing forward) show ``dst``
        instead of ``src + 1``. Played backward the mirror ``dst + 1 -> src + 1`` holds.
    cost : (M,) float64
        Diagonally filtered frame distance of each transition (``D'[src + 1, dst]``).
    future_cost : (M,) float64
        Cost including the anticipated future (the Q-learning iteration), used for ``prob``.
    prob : (M,) float64
        Probability of taking the transition at each forward visit of ``src``; per source
        frame the probabilities sum to at most 1 (exactly 1 at ``exit_frame``).
    exit_frame : int
        Last frame of forward-only playback: it always jumps there (no dead end).
    info : dict
        Analysis parameters and diagnostics, stored as attributes.
    """

    sym_raw: np.ndarray
    symmetry: np.ndarray
    reduced: np.ndarray
    turn_points: np.ndarray
    p_max: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    cost: np.ndarray
    future_cost: np.ndarray
    prob: np.ndarray
    exit_frame: int
    info: dict = field(default_factory=dict)
    #: optional: the flow of the crossfades' frame pairs (None: jumps crossfade plainly)
    flow: FlowModel | None = None

    @property
    def n_frames(self) -> int:
        return int(self.symmetry.shape[0])

    @property
    def first_turn(self) -> int:
        return int(self.turn_points[0])

    @property
    def last_turn(self) -> int:
        return int(self.turn_points[-1])

    def summary(self) -> str:
        """One line: turn points (the first twelve), transitions, exit frame."""
        info = self.info
        return (
            f"{info.get('n_turn_points', 0)} turn points {self.turn_points.tolist()[:12]}, "
            f"{info.get('n_transitions', 0)} transitions, exit frame {self.exit_frame}"
        )


def write(group: h5py.Group, model: TurnPointModel) -> None:
    for name in _PER_FRAME + _PER_TRANSITION:
        group.create_dataset(name, data=np.asarray(getattr(model, name), np.float64))
    for name in ("turn_points", "src", "dst"):
        group.create_dataset(name, data=np.asarray(getattr(model, name), np.int32))
    group.attrs["n_frames"] = model.n_frames
    group.attrs["exit_frame"] = int(model.exit_frame)
    for key, value in model.info.items():
        if key not in ("n_frames", "exit_frame"):
            group.attrs[key] = value
    if model.flow is not None:
        arrays = {
            "pairs": np.asarray(model.flow.pairs, np.int32).reshape(-1, 2),
            "flows": np.asarray(model.flow.flows, np.int16),
        }
        write_part(group, FLOW_GROUP, FLOW_VERSION, arrays, attrs={"step": int(model.flow.step)}, rows=("flows",))


def read(group: h5py.Group, check: Checker, source: SourceInfo) -> TurnPointModel:
    t = check.attr(group, "n_frames", int)
    if t != source.n_frames:
        check.fail(group.name + "@n_frames", f"{t} differs from the source's {source.n_frames} frames")
    exit_frame = check.attr(group, "exit_frame", int)
    if not 1 <= exit_frame < t:
        check.fail(group.name + "@exit_frame", f"{exit_frame} out of range 1..{t - 1}")
    ds = check.dataset
    arrays = {name: ds(group, name, kind="f", shape=(t,)) for name in _PER_FRAME}
    turns = ds(group, "turn_points", kind="iu", shape=(range(t + 1),))
    src = ds(group, "src", kind="iu", shape=(range(t * (t - 1) + 1),))  # one per ordered pair at most
    m = src.shape[0]
    dst = ds(group, "dst", kind="iu", shape=(m,))
    per_tr = {name: ds(group, name, kind="f", shape=(m,)) for name in _PER_TRANSITION}
    base = group.name
    for name in ("symmetry", "reduced"):
        a = arrays[name]
        if a.min() < 0 or a.max() > 1:
            check.fail(f"{base}/{name}", "values outside [0, 1]")
    pm = arrays["p_max"]
    if pm.min() < 0 or pm.max() > 1:
        check.fail(f"{base}/p_max", "probabilities outside [0, 1]")
    if turns.shape[0] < 2:
        check.fail(f"{base}/turn_points", f"holds {turns.shape[0]} turn points; playback needs at least 2")
    check.index_range(f"{base}/turn_points", turns, t)
    if np.any(np.diff(turns.astype(np.int64)) <= 0):
        check.fail(f"{base}/turn_points", "indices are not strictly increasing")
    for name, arr in (("src", src), ("dst", dst)):
        check.index_range(f"{base}/{name}", arr, t)
    if m and np.any(src.astype(np.int64) >= t - 1):
        check.fail(f"{base}/src", "a transition leaves the last frame (it has no successor to replace)")
    prob = per_tr["prob"]
    if m and (prob.min() < 0 or prob.max() > 1):
        check.fail(f"{base}/prob", "probabilities outside [0, 1]")
    sums = np.bincount(src.astype(np.int64), weights=prob, minlength=t) if m else np.zeros(t)
    if sums.max(initial=0.0) > 1 + 1e-6:
        check.fail(f"{base}/prob", "probabilities of one source frame sum to more than 1")
    if m and not np.any((src == exit_frame) & (dst < exit_frame)):
        check.fail(f"{base}@exit_frame", "the exit frame has no backward transition (forward playback would dead-end)")
    if m and np.any((src.astype(np.int64) > exit_frame) | (dst.astype(np.int64) > exit_frame)):
        check.fail(f"{base}/src", "a transition lies beyond the exit frame")
    info = check.info(group)
    flow = _read_flow(group, check, source) if m else None
    return TurnPointModel(
        turn_points=turns.astype(np.int32),
        src=src.astype(np.int32),
        dst=dst.astype(np.int32),
        exit_frame=exit_frame,
        info=info,
        flow=flow,
        **arrays,
        **per_tr,
    )


def _read_flow(group: h5py.Group, check: Checker, source: SourceInfo) -> FlowModel | None:
    """The validated ``flow`` part, or None when absent or of a newer version."""
    g = open_part(group, FLOW_GROUP, FLOW_VERSION, check)
    if g is None:
        return None
    step = check.attr(g, "step", int)
    if step < 1 or step > MAX_FLOW_STEP or step & (step - 1):
        check.fail(g.name + "@step", f"{step} is not a power of two in 1..{MAX_FLOW_STEP}")
    t, h, w = source.n_frames, source.height, source.width
    gh, gw = flow_grid(h, w, step)
    pairs = check.dataset(g, "pairs", kind="iu", shape=(range(t * (t - 1) // 2 + 1), 2))
    flows = check.dataset(g, "flows", kind="i", shape=(pairs.shape[0], gh, gw, 2))
    exact_dtype(check, g.name + "/flows", flows, np.int16)
    check.index_range(g.name + "/pairs", pairs, t)
    pairs = pairs.astype(np.int64)
    if np.any(pairs[:, 0] == pairs[:, 1]):
        check.fail(g.name + "/pairs", "a pair names one frame twice")
    key = np.minimum(pairs[:, 0], pairs[:, 1]) * t + np.maximum(pairs[:, 0], pairs[:, 1])
    if np.unique(key).size != key.size:
        check.fail(g.name + "/pairs", "a pair is stored twice")
    return FlowModel(pairs=pairs.astype(np.int32), flows=np.ascontiguousarray(flows), step=step)
