"""The analysis methods by name: what ``dynatex analyze --methods`` can run, and their parameters.

Each entry names a function ``learn(clip, *, progress=None, **params) -> model`` whose
model the tile database stores under the method's group, whether the method plays from
the stored source frames, and the parameters it takes (:class:`~dynatex.params.Param`:
keyword, rule, default, what it does, command-line option). ``dynatex analyze`` builds its
per-method options and the keyword arguments of each learn function from these
declarations, so a new parameter is declared here and nowhere else. A parameter the command
line does not offer (``flag=None``) is declared too: every learn function checks its arguments
by these rules (:func:`check_params`), and checks by hand only bounds that depend on the data
(a block no larger than the frame) or on another parameter (``k <= n``).

A parameter whose kind is :class:`Clips` takes more clips (the tiles' ``mix``): paths are
decoded by :func:`~dynatex.analyzer.corpus.learn_into` with the main clip's options.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..checks import MAX_COUNT, MAX_SEED, MAX_SIDE, Choice, Either, Flag, Kind, Range, Size, Text
from ..errors import ArgumentTypeError, InvalidArgumentError
from ..params import Param
from ..tiledb.tiles import CONSTRUCTIONS as TILE_CONSTRUCTIONS
from .tone import SATURATION_SHARE


class Clips(Kind):
    """More clips for a method: paths, :class:`~dynatex.analyzer.Clip` objects or frame arrays.

    On the command line the option takes one path and may be repeated (``repeat``);
    :func:`~dynatex.analyzer.corpus.learn_into` decodes the paths.
    """

    metavar = "CLIP"
    repeat = True

    def check(self, name: str, value: Any) -> tuple:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
            raise ArgumentTypeError(f"{name} must be a sequence of clips, not {value!r}")
        return tuple(value)

    def parse(self, text: str) -> str:
        return Text().check("clip", text)

    def describe(self) -> str:
        return "a clip (repeatable)"


class Names(Kind):
    """Names, ``A,B,...`` on the command line (a list in Python).

    >>> Names().parse(" calm, wild")
    ['calm', 'wild']
    """

    metavar = "A,B,..."

    def check(self, name: str, value: Any) -> list[str]:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
            raise ArgumentTypeError(f"{name} must be a sequence of names, not {value!r}")
        return [Text().check(f"{name} item", v) for v in value]

    def parse(self, text: str) -> list[str]:
        names = [n.strip() for n in text.split(",")]
        if not all(names):
            raise InvalidArgumentError(f"expected comma-separated names, none empty, not {text!r}")
        return names

    def describe(self) -> str:
        return "comma-separated names"


_COUNT = Range(int, 1, MAX_COUNT)
_SIDE_OR_SIZE = Either(Range(int, 1, MAX_SIDE), Size(MAX_SIDE), metavar="N or WxH")
_OPEN_UNIT = Range(float, 0.0, 1.0, low_open=True)
_SEED = Range(int, 0, MAX_SEED)
#: learn a projection model on Gaussianised values (analyzer/tone.py)
_TONE = Choice("auto", "on", "off")
_TONE_DOC = (
    "Learn on each channel's levels Gaussianised (a tone map the player maps back): keeps the energy of "
    "clips whose values pile at 0 and 255. auto: where a Gaussian per value would saturate over "
    f"{SATURATION_SHARE:.0%} of them."
)
#: smooth away a compressed clip's block grid before learning (analyzer/deblock.py)
_DEBLOCK = Choice("auto", "on", "off")
_DEBLOCK_DOC = (
    "Smooth away the block grid a compressed clip carries (8 px luma, 16 px chroma blocks) before "
    "learning, so that the model does not recombine it into mismatched squares. auto: where one is found."
)
#: largest pole magnitude of a projection model's dynamics
_MAX_RADIUS = Range(float, 0.0, 1.0, low_open=True, high_open=True)


def _count(name: str, default: Any, doc: str, flag: str = "", **kw: Any) -> Param:
    """A count parameter (an integer >= 1), the most common kind."""
    return Param(name, _COUNT, default, doc, flag, **kw)


LDS_PARAMS = (
    Param(
        "n",
        Either(_COUNT, Choice("auto"), metavar="N"),
        50,
        "State order, or 'auto' for the smallest order that keeps --energy of the variance.",
    ),
    _count("k", None, "Rank of the driving noise.", optional=True, default_doc="n"),
    Param("energy", _OPEN_UNIT, 0.9, "Variance kept by --n auto."),
    Param(
        "svd",
        Choice("auto", "gram", "randomized"),
        "auto",
        "SVD of the frames: gram (exact), randomized (long clips), auto (gram up to 1500 frames).",
    ),
    Param("max_radius", _MAX_RADIUS, 0.995, "Largest pole magnitude."),
    Param("tone", _TONE, "auto", _TONE_DOC),
    Param("deblock", _DEBLOCK, "auto", _DEBLOCK_DOC),
    Param(
        "calibrate",
        Flag(),
        True,
        "Scale the noise so that the states keep the training variance (with a tone map, so that the "
        "draws keep in levels the variance the training reconstructions have there).",
        None,
    ),
    Param("seed", _SEED, 0, "Seed of the randomized SVD and of the detail's phases.", None),
)

TURNPOINT_PARAMS = (
    _count("n", 4, "Mirrored frame pairs of the symmetry test.", "--tp-n"),
    Param("s", Range(int, 0, MAX_COUNT), 1, "Binomial smoothness, s < n/2.", "--tp-s"),
    _count("r", 4, "Turn points are more than R frames apart.", "--tp-r"),
    Param("min_symmetry", Range(float, 0.0, 1.0, high_open=True), 0.3, "Weakest turn point.", "--tp-min-symmetry"),
    Param(
        "max_cost",
        Range(float, 0.0, 1e6, low_open=True),
        2.0,
        "Drop transitions costlier than this many median frame steps.",
        "--tp-max-cost",
    ),
    Param(
        "max_ghost",
        Range(float, 0.0, 1e6),
        1.0,
        "Drop transitions whose crossfade shows double images beyond this many times the source's own "
        "level (0: keep them).",
        "--tp-max-ghost",
    ),
    Param(
        "warp",
        Choice("on", "off"),
        "on",
        "Motion-compensated jump crossfades (optical flow stored) where they show fewer double images.",
        "--tp-warp",
    ),
    # Python only
    _count("min_pairs", 2, "Fewest mirrored pairs a frame near the clip's ends needs, at most n.", None),
    Param("feature_size", Range(int, 4, MAX_SIDE), 64, "Longer side of the frames compared.", None),
    _count("taps", 2, "Half-length of the diagonal filter of the transition costs.", None),
    Param("p", Range(float, 0.0, 10.0, low_open=True), 2.0, "Exponent on the filtered cost.", None),
    Param("alpha", Range(float, 0.0, 1.0, low_open=True, high_open=True), 0.999, "Future-cost discount.", None),
    Param("sigma", Range(float, 0.0, 100.0, low_open=True), 0.1, "Probability scale of the costs.", None),
    _count("min_gap", 6, "Transitions to within this many frames of the successor are dropped.", None),
    Param("min_prob", Range(float, 0.0, 1.0, high_open=True), 0.02, "Least probability per visit kept.", None),
    _count("max_per_frame", 3, "Most transitions kept per source frame.", None),
)

MIXTURE_PARAMS = (
    _count("components", 3, "PPCA components S.", "--mix-components"),
    _count("dim", 10, "Dimension d of each component.", "--mix-dim"),
    _count("global_dim", None, "Global coordinates D.", "--mix-global-dim", optional=True, default_doc="d"),
    _count("pca_dim", 50, "Dimension of the reduced PCA space.", "--mix-pca-dim"),
    _count("neighbors", 12, "LLE neighbours K.", "--mix-neighbors"),
    _count(
        "pmax",
        None,
        "Largest AR order tried.",
        "--mix-pmax",
        optional=True,
        default_doc="5, or less when the clip is short",
    ),
    Param("tone", _TONE, "auto", _TONE_DOC, "--mix-tone"),
    Param("deblock", _DEBLOCK, "auto", _DEBLOCK_DOC, "--mix-deblock"),
    Param(
        "residual",
        Choice("auto", "on", "off"),
        "auto",
        "Play what the components leave out of each frame inside the reduced PCA space as a process of "
        "its own (principal axes of the residual, AR(2) each; at most 30% more basis rows) instead of "
        "dropping it: auto where the detail part is refused (a coarse residual) or not learned (a "
        "streamed clip), on always (the detail then models what is left), off never.",
        "--mix-residual",
    ),
    # Python only
    Param("max_radius", _MAX_RADIUS, 0.995, "Largest pole magnitude of the AR dynamics.", None),
    _count("max_iter", 200, "Most EM iterations.", None),
    Param("tol", Range(float, 0.0, 1.0, low_open=True, high_open=True), 1e-6, "EM stops below this gain.", None),
    Param("seed", _SEED, 0, "Seed of the EM initialisation and the randomized SVD.", None),
)

TILES_PARAMS = (
    Param(
        "tile",
        Either(Range(int, 8, MAX_SIDE), Size(MAX_SIDE, 8), metavar="N or WxH"),
        None,
        "Tile size in pixels; with the quilted construction the quilt block size N.",
        optional=True,
        default_doc="from the dominant spatial period; quilted: a third of the shorter side (under 128 px at least 32)",
    ),
    Param(
        "construction",
        Choice(*TILE_CONSTRUCTIONS),
        None,
        "How tiles join. quilted: one large seamless torus quilted from the clip, cut into cells laid out in "
        "order, no lattice; ring: tiles share one boundary ring and join in any arrangement; wang: "
        "edge-coloured tiles that join where colours match (one texture only).",
        "--tiles-construction",
        optional=True,
        default_doc="quilted for one texture, ring with --tiles-mix, --tiles-n or --tiles-ring",
    ),
    Param(
        "period",
        Size(MAX_SIDE),
        None,
        "Quilted: period of the torus.",
        "--tiles-period",
        optional=True,
        default_doc="at least 512 and twice the clip per side",
    ),
    Param(
        "n_tiles",
        Range(int, 1, 64),
        None,
        "Tiles per texture with the ring construction.",
        "--tiles-n",
        optional=True,
        default_doc="4",
    ),
    Param("edge_colours", Range(int, 2, 4), 2, "Wang edge colours per direction (2: 8 tiles).", "--tiles-edge-colours"),
    Param("min_loop", Range(int, 2, MAX_COUNT), 32, "Shortest loop in frames.", "--tiles-min-loop"),
    _count("max_loop", None, "Longest loop in frames.", "--tiles-max-loop", optional=True, default_doc="the clip"),
    _count("transition", 8, "Frames over which the per-pixel temporal transitions spread.", "--tiles-transition"),
    Param(
        "ring",
        Range(int, 2, MAX_SIDE),
        None,
        "Width of the band of the shared ring cuts.",
        "--tiles-ring",
        optional=True,
        default_doc="tile/10",
    ),
    Param(
        "flow_gain",
        Range(float, 0.0, 10.0),
        0.5,
        "Extra cut freedom per pixel/frame of optical flow (0 = off).",
        "--tiles-flow-gain",
    ),
    Param(
        "mix",
        Clips(),
        (),
        "Another texture to mix with: cut to the same tiles, with border tiles.",
        "--tiles-mix",
        default_doc="none",
    ),
    Param(
        "names",
        Names(),
        None,
        "Class names of the main and the --tiles-mix textures.",
        "--tiles-names",
        optional=True,
        default_doc="main,mix1,...",
    ),
    # Python only
    Param("min_tile", Range(int, 8, MAX_SIDE), 32, "Smallest tile side taken from the spatial period.", None),
    Param("max_tile", Range(int, 8, MAX_SIDE), 256, "Largest tile side taken from the spatial period.", None),
    Param(
        "overlap",
        Range(int, 2, MAX_SIDE),
        None,
        "Width of the toroidal overlap bands.",
        None,
        optional=True,
        default_doc="tile/4 plus twice the mean flow",
    ),
    Param(
        "feather",
        Range(int, 0, MAX_SIDE),
        None,
        "Border tiles fade the other texture's strip over this many pixels past the cut.",
        None,
        optional=True,
        default_doc="max(ring, tile/5)",
    ),
    Param("seed", _SEED, 0, "Seed of the quilted construction's random picks.", None),
)

QUILT_PARAMS = (
    Param(
        "size",
        Size(MAX_SIDE),
        None,
        "Output canvas.",
        "--quilt-size",
        optional=True,
        default_doc="twice the clip's width and height",
    ),
    Param(
        "block",
        Either(Range(int, 2, MAX_SIDE), Size(MAX_SIDE, 2), metavar="N or WxH"),
        28,
        "Block size; elongated blocks (e.g. 16x64) suit stretching features.",
        "--quilt-block",
    ),
    Param(
        "overlap",
        _SIDE_OR_SIZE,
        None,
        "Block overlap.",
        "--quilt-overlap",
        optional=True,
        default_doc="5/16 of the block",
    ),
    _count(
        "rank",
        15,
        "SVD rank of the block comparisons (None in Python: full time sequences).",
        "--quilt-rank",
        optional=True,
    ),
    Param(
        "tolerance",
        Range(float, 0.0, 1e6),
        0.1,
        "Pick among candidates within (1 + T) of the best error.",
        "--quilt-tolerance",
    ),
    Param(
        "feather",
        Range(int, 0, MAX_SIDE),
        None,
        "Cross-fade half-width across cuts (0 = hard cuts).",
        "--quilt-feather",
        optional=True,
        default_doc="overlap/2",
    ),
    Param(
        "lowpass",
        Range(float, 0.0, float(MAX_SIDE), low_open=True),
        None,
        "Low-pass gain normalisation with this Gaussian sigma in pixels.",
        "--quilt-lowpass",
        optional=True,
        default_doc="off",
        extra={"metavar": "SIGMA"},
    ),
    Param(
        "restore_gradient",
        Flag(),
        False,
        "With --quilt-lowpass: keep the source's low-frequency gradient instead of flattening it.",
        "--quilt-restore-gradient",
    ),
    Param("seed", _SEED, 0, "Seed of the random block choices.", "--quilt-seed"),
    Param("balance", Flag(), False, "Weight each frame by its own contrast in the comparisons and cuts.", None),
)


@dataclass(frozen=True)
class Method:
    """One analysis method: its learn function, whether it stores frames, its parameters.

    Examples
    --------
    >>> m = get_method("turnpoints")
    >>> m.param("n").flag_name, m.param("n").default
    ('--tp-n', 4)
    """

    name: str
    target: str  # "module:function" inside dynatex.analyzer, or a full "package.module:function"
    needs_frames: bool  # store the clip's frames beside the model
    summary: str
    params: tuple[Param, ...] = ()

    def function(self) -> Callable[..., Any]:
        module, func = self.target.split(":")
        package = module if "." in module else f"dynatex.analyzer.{module}"
        return getattr(importlib.import_module(package), func)

    def param(self, name: str) -> Param:
        """The declared parameter ``name``."""
        for p in self.params:
            if p.name == name:
                return p
        raise InvalidArgumentError(
            f"method {self.name} has no parameter {name!r} (it has {', '.join(p.name for p in self.params) or 'none'})"
        )


METHODS: dict[str, Method] = {
    "lds": Method("lds", "lds:learn_lds", False, "linear dynamic texture (Doretto & Soatto)", LDS_PARAMS),
    "turnpoints": Method(
        "turnpoints",
        "turnpoints:learn_turnpoints",
        True,
        "video texture with turn points and transitions (Van Haevre; Schoedl)",
        TURNPOINT_PARAMS,
    ),
    "mixture": Method(
        "mixture",
        "mixture:learn_mixture",
        False,
        "subspace mixture + global coordination + AR(p) (Liu, Lin & Ahuja)",
        MIXTURE_PARAMS,
    ),
    "tiles": Method(
        "tiles",
        "tiles:learn_tiles",
        False,
        "triple toroid-shaped tiles, mixing and tone (Richtr & Haindl)",
        TILES_PARAMS,
    ),
    "quilt": Method(
        "quilt",
        "quilt:learn_quilt",
        True,
        "time-varying texture: SVD-accelerated quilting of spatio-temporal cuboids",
        QUILT_PARAMS,
    ),
}


def check_params(method: str, **values: Any) -> tuple[Any, ...]:
    """``values`` (keyword arguments of ``method``'s learn function), each checked and normalized by
    its declared rule (:meth:`~dynatex.params.Param.check`), in the order given.

    The one check of a method parameter: the command line parses by the same declarations, and
    every learn function calls this first. An error is one line naming the parameter.

    Examples
    --------
    >>> check_params("tiles", n_tiles=3, flow_gain=1)
    (3, 1.0)
    >>> check_params("tiles", edge_colours=5)
    Traceback (most recent call last):
    ...
    dynatex.errors.InvalidArgumentError: edge_colours must be an integer in 2..4, not 5
    """
    m = get_method(method)
    return tuple(m.param(name).check(value) for name, value in values.items())


#: ``--methods auto``: the methods that can suit the clip, ranked by playing them (:mod:`.auto`)
AUTO = "auto"


def get_method(name: str) -> Method:
    """The method ``name``, or an :class:`~dynatex.errors.InvalidArgumentError` naming the methods."""
    if name not in METHODS:
        raise InvalidArgumentError(f"method must be one of {sorted(METHODS)}, not {name!r}")
    return METHODS[name]
