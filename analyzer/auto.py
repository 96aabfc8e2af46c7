"""``--methods auto``: the methods that can suit a clip, each played against the source and ranked.

:func:`choose_methods` looks at the clip: a linear dynamic texture (``lds``) is the baseline for
any clip; the subspace mixture suits a clip without a time-varying trend (it models a
stationary process); the turn-point video texture plays the clip's own frames and suits any
clip long enough to reverse in; tiles need a clip that is one texture all over (spatial
stationarity, :func:`~dynatex.analyzer.tiles.stationarity`); the time-varying quilt (mode
``evolve``) needs a trend over time (:func:`time_trend`). :func:`rank` plays each learned mode
from the database against the source frames, judges the figures with the calibrated bands of
:mod:`~dynatex.analyzer.verdicts` and orders the modes: fewest poor and bad figures first
(:func:`~dynatex.analyzer.verdicts.score`), then the nearest spectrum, then the most coherent
patches. The first becomes the texture's ``default_mode``; the list is stored as its ``ranking``
(``tiledb/FORMAT.md``) and ``dynatex info`` prints it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..tiledb.database import MODE_METHOD

#: share of the frames' feature variance a linear trend in time must explain for a time-varying texture
TREND_MIN = 0.4
#: frames a clip needs for the turn-point texture (a symmetry test of 4 pairs either side, and room to turn)
TURNPOINT_MIN_FRAMES = 24
#: modes that play the clip's time-lapse once (then hold): judged over the clip's length, not longer
TIME_LAPSE_MODES = ("evolve",)
#: method -> the player mode that plays it (the modes declare their methods; tiledb knows the pairs)
MODE_OF = {method: mode for mode, method in MODE_METHOD.items()}


@dataclass(frozen=True)
class Choice:
    """A method considered for a clip: whether it runs and why."""

    method: str
    chosen: bool
    reason: str


def time_trend(frames: np.ndarray) -> float:
    """Share (0..1) of the variance of the frames' thumbnails that a straight line in time explains.

    A stationary texture (waves, fire, grass in wind) fluctuates about its mean: near 0 (sea 0.09).
    A time-lapse of rust or melting drifts one way: near 1.

    >>> t = np.linspace(0, 1, 30)[:, None, None, None]
    >>> round(time_trend((t * 200 + np.zeros((30, 16, 16, 3))).astype(np.uint8)), 2)
    1.0
    """
    from .turnpoints import frame_features

    f = frame_features(frames).astype(np.float64)
    f -= f.mean(axis=0)
    total = float((f * f).sum())
    if total <= 0:
        return 0.0
    t = np.arange(len(f)) - (len(f) - 1) / 2
    beta = t @ f / (t @ t)
    return float(min(1.0, (t @ t) * float(beta @ beta) / total))


def choose_methods(frames: np.ndarray) -> list[Choice]:
    """Every method, with whether it can suit the clip ``frames`` ``(T, H, W, C)`` and why."""
    from ..tiledb.tiles import STATIONARITY_WARN
    from .tiles import stationarity

    trend = time_trend(frames)
    stat = stationarity(frames)[0]
    t = frames.shape[0]
    drifting = trend >= TREND_MIN
    return [
        Choice("lds", True, "linear dynamic texture: the baseline for any clip"),
        Choice(
            "mixture",
            not drifting,
            f"stationary in time (trend {trend:.2f} < {TREND_MIN})"
            if not drifting
            else f"drifts over time (trend {trend:.2f} >= {TREND_MIN}); the mixture models a stationary process",
        ),
        Choice(
            "turnpoints",
            t >= TURNPOINT_MIN_FRAMES,
            f"plays the clip's own frames, turning at symmetric frames ({t} frames)"
            if t >= TURNPOINT_MIN_FRAMES
            else f"{t} frames are too few to turn in (at least {TURNPOINT_MIN_FRAMES})",
        ),
        Choice(
            "tiles",
            stat >= STATIONARITY_WARN,
            f"one texture all over (stationarity {stat:.2f} >= {STATIONARITY_WARN})"
            if stat >= STATIONARITY_WARN
            else f"not one texture all over (stationarity {stat:.2f} < {STATIONARITY_WARN}): tiles repeat its objects",
        ),
        Choice(
            "quilt",
            drifting,
            f"a time-varying texture (trend {trend:.2f} >= {TREND_MIN})"
            if drifting
            else f"no trend over time (trend {trend:.2f} < {TREND_MIN}); the quilt is for time-lapses",
        ),
    ]


def learn_chosen(
    writer: Any,
    texture: str,
    clip: Any,
    methods: list[str],
    *,
    params: dict[str, dict] | None = None,
    progress: Any = None,
    on_model: Any = None,
) -> tuple[list[str], dict[str, str]]:
    """Put texture ``texture`` from ``clip`` into ``writer`` with each of ``methods`` that learns.

    A method whose learning fails with a dynatex error (the clip does not support it, e.g. too
    few frames for the mixture's components) is left out. Returns the methods stored and the
    reason each other one failed.
    """
    import time

    from ..errors import DynatexError, InvalidArgumentError
    from .methods import get_method

    bar = progress or (lambda stage: None)
    writer.put_texture(texture, clip.source_info())
    learned: list[str] = []
    failed: dict[str, str] = {}
    frames_written = False
    for name in methods:
        m = get_method(name)
        t = time.perf_counter()
        try:
            model = m.function()(clip, progress=bar(name), **(params or {}).get(name, {}))
        except (DynatexError, ValueError, np.linalg.LinAlgError) as exc:
            failed[name] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            continue
        if m.needs_frames and not frames_written:
            writer.put_frames(texture, clip.frames)
            frames_written = True
        writer.put_method(texture, name, model)
        learned.append(name)
        if on_model is not None:
            on_model(name, model, time.perf_counter() - t)
    if not learned:
        raise InvalidArgumentError(f"--methods auto: no method could learn the clip ({'; '.join(failed.values())})")
    return learned, failed


def play_mode(db: str | os.PathLike, texture: str, mode: str, frames: int, *, seed: int = 0) -> np.ndarray:
    """``frames`` frames of ``mode`` from the database, at the source's size where the mode plays any size."""
    from ..player import open_player, player_class
    from ..tiledb import open_db

    opts: dict[str, Any] = {"seed": seed}
    with open_db(db) as opened:  # the source's size, without building a player for it
        src = opened.texture(texture).source
        shape = (int(src.height), int(src.width))
    if player_class(mode).capabilities.any_size:  # evolve plays its stored canvas, not any size
        opts["size"] = shape
    with open_player(db, texture, mode=mode, **opts) as player:
        out = np.empty((frames,) + tuple(player.shape), np.uint8)
        for i in range(frames):
            player.next_frame(out=out[i])
    return out


def rank(
    db: str | os.PathLike,
    texture: str,
    source: np.ndarray,
    modes: list[str],
    *,
    frames: int = 200,
    seed: int = 0,
    reasons: dict[str, str] | None = None,
    progress: Any = None,
) -> list[dict[str, Any]]:
    """Play each of ``modes`` from ``db`` and rank them against the ``source`` frames, best first.

    Each entry: ``mode``, ``rank`` (1 is best), ``verdict`` (the worst figure's), ``score`` (poor
    1, bad 3 per figure), the judged ``figures`` ``{figure: [value, verdict]}``, ``why`` (one line
    of the figures that decided) and ``reason`` (why the method was chosen, from ``reasons``).
    """
    from ..errors import DynatexError
    from .metrics import evaluate
    from .metrics.memo import remembering
    from .verdicts import judge, score, worst

    entries: list[dict[str, Any]] = []
    with remembering(source):  # the source side of every metric, once for all the modes
        for i, mode in enumerate(modes):
            try:
                n = min(frames, len(source)) if mode in TIME_LAPSE_MODES else frames
                out = play_mode(db, texture, mode, n, seed=seed)
            except DynatexError as exc:  # e.g. no verified OpenCL device the mode insists on
                entries.append({"mode": mode, "verdict": "failed", "score": None, "why": f"cannot play: {exc}"})
                continue
            report = evaluate(out, source, seed=seed, n_samples=300)
            v = judge(report)
            figures = {x["figure"]: [_rounded(x["value"]), x["verdict"]] for x in v if x["verdict"] != "n/a"}
            entries.append(
                {
                    "mode": mode,
                    "verdict": worst(v),
                    "score": score(v),
                    "figures": figures,
                    "spectrum_distance_db": _rounded(report.get("spectrum_distance_db")),
                    "patch_coherence": _rounded(report.get("patch_coherence")),
                    "why": _why(v),
                    "reason": (reasons or {}).get(mode, ""),
                }
            )
            if progress is not None:
                progress(i + 1, len(modes))
    entries.sort(key=_order)
    for i, e in enumerate(entries):
        e["rank"] = i + 1
    return entries


def _order(entry: dict[str, Any]) -> tuple[float, float, float]:
    spec = entry.get("spectrum_distance_db")
    coh = entry.get("patch_coherence")
    sc = entry["score"]
    return (math.inf if sc is None else sc, math.inf if spec is None else spec, math.inf if coh is None else coh)


def _rounded(v: Any) -> Any:
    if isinstance(v, list):
        return [_rounded(x) for x in v]
    if isinstance(v, float):
        return round(v, 4) if math.isfinite(v) else None
    return v


def _why(verdicts: list[dict[str, Any]]) -> str:
    """``"bad: frame step ratio 0.35; poor: spectrum distance (dB) 1.4; good: 4 more"``."""
    parts = []
    for level in ("bad", "poor"):
        items = [f"{x['label']} {_text(x['value'])}" for x in verdicts if x["verdict"] == level]
        if items:
            parts.append(f"{level}: {', '.join(items)}")
    good = sum(x["verdict"] == "good" for x in verdicts)
    parts.append(f"{good} good" if parts else f"all {good} judged figures good")
    return "; ".join(parts)


def _text(value: Any) -> str:
    if isinstance(value, list):
        return "/".join(_text(v) for v in value)
    if isinstance(value, float):
        return f"{value:.3g}"
    return "none" if value is None else str(value)


__all__ = ["MODE_OF", "TREND_MIN", "Choice", "choose_methods", "learn_chosen", "play_mode", "rank", "time_trend"]
