"""A seeded tile-database mutator and a crash-proof runner for it (used by ``test_fuzz.py``
and ``tools/fuzz_databases.py``).

Small real databases, one per method, are built with the analyzer; mutant ``i`` of seed
``s`` is a copy of one of them changed in one way (a byte flip, a truncation, a value,
an index, a shape, a dtype, an attribute), chosen by a generator seeded with ``(s, i)`` so
that any mutant can be rebuilt from its number. Each mutant goes through ``dynatex info``
(open and validate everything) and a short render on the numpy backend and on one verified
OpenCL device, in a worker process: a segfault or a hang costs the worker, never the caller.
A worker handles mutants one after another (process start-up and kernel builds are paid
once); when one dies or overruns its time, the mutant it held is recorded as a crash or a
hang and a fresh worker takes the next.

The structural mutants (:data:`STRUCTURAL`, :func:`plan_structural`) use HDF5's own features
instead: a dataset's data in external storage (a file the mutator writes with the dataset's own
bytes, or a FIFO), a virtual dataset over a foreign HDF5 file (or a missing one), an external or
soft link in place of a dataset or group (the foreign file holding a faithful copy), and size
bombs (a dataset grown to declare :data:`BOMB_BYTES`, gzip- or LZF-compressed zeros, or never
written). A database reads only itself, so a link mutant must be rejected; each worker reports
its own and its probe children's peak resident memory, so a bomb that got read shows.

Outcomes, per mutant (the worst of its steps):

- ``rejected``: a :class:`~dynatex.tiledb.DynatexError` with a one-line message;
- ``ok``: opened, validated and rendered;
- ``garbage``: passed validation, but the frames of a backend are flat (one value) or
  frozen (identical in time) where the unmutated database's are not;
- ``error``: any other exception, or a multi-line message;
- ``foreign``: a structural link mutant (external storage, virtual dataset, external or soft
  link) passed a step: it read, or could have read, data from outside the file;
- ``crash``: the worker died (a signal);
- ``hang``: the worker overran its time.

Run ``python tests/tiledb/fuzzing.py --worker`` only through :class:`Runner`.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: method group -> player mode that plays it
METHOD_MODES = {"lds": "lds", "mixture": "mixture", "quilt": "evolve", "tiles": "tiles", "turnpoints": "turnpoints"}
KINDS = ("byteflip", "truncate", "value", "index", "shape", "dtype", "attr")
#: mutations with HDF5's own features, and their variants; the first four must always be rejected
STRUCTURAL = {
    "external": ("absolute", "relative", "fifo"),
    "virtual": ("foreign", "missing"),
    "extlink": ("dataset", "method", "texture", "source"),
    "softlink": ("moved", "dangling", "loop"),
    "bomb": ("gzip", "lzf", "sparse"),
}
LINKS = ("external", "virtual", "extlink", "softlink")
#: declared bytes of a size bomb
BOMB_BYTES = 2**30
OUTCOMES = ("rejected", "ok", "garbage", "error", "foreign", "crash", "hang")
BAD = ("garbage", "error", "foreign", "crash", "hang")
#: frames rendered per backend, and the player options that keep them small
FRAMES = 4
MODE_OPTIONS = {"tiles": {"size": (40, 24), "tone": "consensus"}, "evolve": {"size": (32, 24), "jitter": 2.0}}
#: pixel stores: any byte is a valid pixel, so overwriting them whole gives a faithfully flat texture
_PIXELS = ("frames", "tiles")
TEXTURE = "t"


# -- the databases ----------------------------------------------------------------------------
def build_bases(folder: str | os.PathLike, *, detail: bool = True) -> dict[str, Path]:
    """One small database per method (texture ``t``, frames stored where the method plays them);
    the lds and mixture models are learned on tone values (their ``tone`` part fuzzed too).
    ``detail=False`` leaves out the lds and mixture models' detail, gamut, tone and residual parts and
    their codec grid's info keys (the layout of the bases before they existed, which fixed byte-flip
    mutants of the regression tests refer to)."""
    from dynatex.analyzer import load_clip
    from dynatex.analyzer.lds import learn_lds
    from dynatex.analyzer.mixture import learn_mixture
    from dynatex.analyzer.quilt import learn_quilt, spreading_clip
    from dynatex.analyzer.tiles import learn_tiles
    from dynatex.analyzer.turnpoints import learn_turnpoints, pendulum_clip
    from dynatex.tiledb import DatabaseWriter

    folder = Path(folder)
    waves = load_clip(_waves(40, 16, 20))
    tone = "on" if detail else "off"
    learners = {
        "lds": (waves, lambda c: learn_lds(c, n=6, tone=tone), False),
        "mixture": (waves, lambda c: learn_mixture(c, components=2, dim=3, tone=tone, residual="on"), False),
        "quilt": (
            load_clip(spreading_clip(12, 16, 16)),
            lambda c: learn_quilt(c, size=(32, 24), block=8, rank=4, seed=0),
            True,
        ),
        "tiles": (
            load_clip(_waves(40, 32, 32, seed=1)),
            lambda c: learn_tiles(c, tile=12, min_loop=12, transition=4),
            False,
        ),
        "turnpoints": (load_clip(pendulum_clip(40, 16)[0]), learn_turnpoints, True),
    }
    out = {}
    for method, (clip, learn, frames) in learners.items():
        path = folder / f"{method}.h5"
        with DatabaseWriter(path, overwrite=True) as w:
            w.put_texture(TEXTURE, clip.source_info())
            if frames:
                w.put_frames(TEXTURE, clip.frames)
            model = learn(clip)
            if not detail and hasattr(model, "detail"):
                model.detail = model.gamut = None
            if not detail and hasattr(model, "residual"):
                model.residual = None
            if not detail:
                for key in ("codec_grid", "deblocked"):
                    model.info.pop(key, None)
            w.put_method(TEXTURE, method, model)
        out[method] = path
    return out


def _waves(t: int, h: int, w: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tt, yy, xx = np.meshgrid(np.arange(t), np.arange(h), np.arange(w), indexing="ij")
    g = np.sin(2 * np.pi * tt / 13 + 0.4 * xx + 0.3 * yy) + np.sin(2 * np.pi * tt / 7 - 0.3 * xx + 0.5 * yy)
    g = np.clip(128 + 50 * g + rng.normal(0, 3, g.shape), 0, 255).astype(np.uint8)
    return np.stack([g, (g * 0.8 + 20).astype(np.uint8), 255 - g], axis=3)


def inventory(path: str | os.PathLike) -> dict[str, Any]:
    """Datasets ``{path: (dtype.str, shape)}`` and attributes ``[(object, name)]`` of a database."""
    import h5py

    datasets: dict[str, tuple[str, tuple[int, ...]]] = {}
    attrs: list[tuple[str, str]] = [("/", k) for k in h5py.File(path, "r").attrs]
    with h5py.File(path, "r") as f:

        def visit(name: str, obj) -> None:
            if isinstance(obj, h5py.Dataset):
                datasets["/" + name] = (obj.dtype.str, tuple(obj.shape))
            attrs.extend(("/" + name, k) for k in obj.attrs)

        f.visititems(visit)
    return {"datasets": datasets, "attrs": sorted(set(attrs)), "size": os.path.getsize(path)}


# -- the mutations ----------------------------------------------------------------------------
_FLOATS = (np.nan, np.inf, -np.inf, 1e308, -1e308, 1e30, -1.0, 0.0, 1e-300, 255.0, 256.0, -256.0)
_INTS = (-1, 0, 1, 2**31 - 1, -(2**31), 255, 256, 65536)
_ATTRS: tuple[Any, ...] = (
    np.nan,
    np.inf,
    -np.inf,
    -1,
    0,
    2**62,
    -(2**62),
    1.5,
    1e308,
    "x",
    "",
    b"\xff\xfe",
    np.array([1, 2, 3]),
    np.array([], np.int64),
    True,
    np.float16(2.0),
    "delete",
)
_DTYPES = ("<f2", "<f4", "<f8", "|i1", "<i2", "<i4", "<i8", "|u1", "<u2", "|b1", "<c8", "|S8")


def plan(seed: int, index: int, inventories: dict[str, dict]) -> dict[str, Any]:
    """The mutation of mutant ``index`` (a plain dict: method, kind and what to change)."""
    rng = np.random.default_rng([seed, index])
    methods = sorted(inventories)
    method = methods[index % len(methods)]
    kind = KINDS[(index // len(methods)) % len(KINDS)]
    inv = inventories[method]
    spec: dict[str, Any] = {"index": index, "seed": seed, "method": method, "kind": kind}
    ds = inv["datasets"]
    names = sorted(ds)
    ints = [
        n
        for n in names
        if ds[n][0][1] in "iu" and not n.endswith("/" + _PIXELS[0]) and not n.endswith("/" + _PIXELS[1])
    ]
    if kind == "byteflip":
        size = inv["size"]
        hi = size if rng.random() < 0.5 else min(size, 4096)
        count = int(rng.integers(1, 9))
        spec["offsets"] = sorted(int(v) for v in rng.integers(0, hi, count))
        spec["xor"] = [int(v) for v in rng.integers(1, 256, count)]
    elif kind == "truncate":
        size = inv["size"]
        spec["length"] = int(rng.integers(0, size)) if rng.random() < 0.7 else size - int(rng.integers(1, 65))
    elif kind == "value":
        target = names[int(rng.integers(len(names)))]
        spec["target"] = target
        is_int = ds[target][0][1] in "iub"
        values = _INTS if is_int else _FLOATS
        spec["value"] = _jsonable(values[int(rng.integers(len(values)))])
        scopes = ["one", "row", "all"] if target.rsplit("/", 1)[-1] not in _PIXELS else ["one", "row"]
        spec["scope"] = scopes[int(rng.integers(len(scopes)))]
        spec["at"] = int(rng.integers(1 << 30))
    elif kind == "index":
        if ints:
            spec["target"] = ints[int(rng.integers(len(ints)))]
            ops = ("minus_one", "past_end", "int_max", "zero", "reverse", "shuffle", "plus_one", "swap_last")
            spec["op"] = ops[int(rng.integers(len(ops)))]
            spec["at"] = int(rng.integers(1 << 30))
        else:  # no integer dataset (lds, mixture): the integer sizes in the attributes
            spec["kind_detail"] = "size attribute"
            int_attrs = [a for a in inv["attrs"] if a[1] in _SIZE_ATTRS]
            obj, name = int_attrs[int(rng.integers(len(int_attrs)))]
            spec["target"], spec["attr"] = obj, name
            spec["value"] = ["minus_one", "plus_one", "zero", "double"][int(rng.integers(4))]
    elif kind == "shape":
        target = names[int(rng.integers(len(names)))]
        spec["target"] = target
        ops = ("drop_last", "add_one", "transpose", "flatten", "lead_axis", "empty", "scalar", "delete")
        spec["op"] = ops[int(rng.integers(len(ops)))]
        ndim = max(1, len(ds[target][1]))
        spec["axis"] = 0 if rng.random() < 0.5 else int(rng.integers(ndim))  # counts sit on axis 0
    elif kind == "dtype":
        target = names[int(rng.integers(len(names)))]
        spec["target"] = target
        choices = [d for d in _DTYPES if d != ds[target][0]]
        spec["dtype"] = choices[int(rng.integers(len(choices)))]
    else:  # attr
        obj, name = inv["attrs"][int(rng.integers(len(inv["attrs"])))]
        spec["target"], spec["attr"] = obj, name
        v = _ATTRS[int(rng.integers(len(_ATTRS)))]
        spec["value"] = v if isinstance(v, str) else _jsonable(v)
    return spec


def plan_structural(seed: int, index: int, inventories: dict[str, dict]) -> dict[str, Any]:
    """The structural mutation of mutant ``index``: method, kind, variant and the dataset it replaces."""
    rng = np.random.default_rng([seed, index, 1])
    methods = sorted(inventories)
    method = methods[index % len(methods)]
    kinds = sorted(STRUCTURAL)
    kind = kinds[(index // len(methods)) % len(kinds)]
    ds = inventories[method]["datasets"]
    targets = sorted(n for n, (_, shape) in ds.items() if len(shape) >= 1 and int(np.prod(shape)) > 0)
    variants = STRUCTURAL[kind]
    variant = variants[(index // (len(methods) * len(kinds))) % len(variants)]
    target = targets[int(rng.integers(len(targets)))]
    parts = target.split("/")  # "", "textures", name, (method,) dataset
    texture = "/".join(parts[:3])
    replaced = {"method": "/".join(parts[:-1]), "texture": texture, "source": texture + "/source"}
    return {
        "index": index,
        "seed": seed,
        "method": method,
        "kind": kind,
        "variant": variant,
        "target": target,
        "object": replaced.get(variant, target) if kind == "extlink" else target,  # what the mutant replaces
    }


_SIZE_ATTRS = (
    "n",
    "k",
    "components",
    "dim",
    "global_dim",
    "order",
    "width",
    "height",
    "n_frames",
    "channels",
    "n_blocks",
    "n_tiles",
    "loop_length",
    "tile_h",
    "tile_w",
    "exit_frame",
    "block_h",
    "block_w",
)


def _jsonable(v: Any) -> Any:
    """A value in JSON (the spec travels to the worker): arrays and odd scalars are tagged."""
    if isinstance(v, bytes):
        return {"bytes": v.hex()}
    if isinstance(v, np.ndarray):
        return {"array": v.tolist(), "dtype": v.dtype.str}
    if isinstance(v, np.float16):
        return {"f16": float(v)}
    if isinstance(v, float) and not np.isfinite(v):
        return {"float": repr(v)}
    if isinstance(v, (bool, np.bool_)):
        return {"bool": bool(v)}
    return v


def _unjson(v: Any) -> Any:
    if isinstance(v, dict):
        if "bytes" in v:
            return bytes.fromhex(v["bytes"])
        if "array" in v:
            return np.asarray(v["array"], dtype=v["dtype"])
        if "f16" in v:
            return np.float16(v["f16"])
        if "float" in v:
            return float(v["float"])
        if "bool" in v:
            return np.bool_(v["bool"])
    return v


def apply(spec: dict[str, Any], base: str | os.PathLike, dest: str | os.PathLike) -> None:
    """Write the mutant ``spec`` describes: a copy of ``base`` at ``dest``, changed."""
    import h5py

    shutil.copyfile(base, dest)
    kind = spec["kind"]
    if kind == "byteflip":
        data = bytearray(Path(dest).read_bytes())
        for off, x in zip(spec["offsets"], spec["xor"]):
            data[off] ^= x
        Path(dest).write_bytes(bytes(data))
        return
    if kind == "truncate":
        with open(dest, "r+b") as f:
            f.truncate(spec["length"])
        return
    with warnings.catch_warnings(), np.errstate(all="ignore"), h5py.File(dest, "r+") as f:
        warnings.simplefilter("ignore")
        if kind in STRUCTURAL:
            _structural(f, spec, Path(dest))
            return
        if kind == "attr" or (kind == "index" and "attr" in spec):
            _mutate_attr(f[spec["target"]], spec)
            return
        target = spec["target"]
        arr = f[target][()]
        new = {"value": _new_value, "index": _new_index, "shape": _new_shape, "dtype": _new_dtype}[kind](arr, spec)
        del f[target]
        if new is not None:
            f[target] = new


def _structural(f, spec: dict[str, Any], dest: Path) -> None:
    """Replace ``spec["target"]`` (or the group holding it) by the structural mutation ``spec`` names."""
    import h5py

    kind, variant, target = spec["kind"], spec["variant"], spec["target"]
    ds = f[target]
    arr, dtype, shape = ds[()], ds.dtype, ds.shape
    foreign = dest.with_name(dest.name + ".foreign")
    for old in (foreign, dest.with_name(dest.name + ".fifo")):
        if old.exists():
            old.unlink()
    if kind == "external":
        if variant == "fifo":
            name = str(dest.with_name(dest.name + ".fifo"))
            os.mkfifo(name)
        else:
            foreign.write_bytes(arr.tobytes())  # the dataset's own bytes: only where they lie is wrong
            name = str(foreign) if variant == "absolute" else os.path.relpath(foreign)
        del f[target]
        f.create_dataset(target, shape=shape, dtype=dtype, external=[(name, 0, arr.nbytes)])
    elif kind == "virtual":
        with h5py.File(foreign, "w") as g:
            g["data"] = arr
        if variant == "missing":
            foreign.unlink()
        layout = h5py.VirtualLayout(shape=shape, dtype=dtype)
        layout[...] = h5py.VirtualSource(str(foreign), "data", shape=shape, dtype=dtype)
        del f[target]
        f.create_virtual_dataset(target, layout)
    elif kind == "extlink":
        obj = spec["object"]
        with h5py.File(foreign, "w") as g:
            f.copy(f[obj], g, name="copy")  # a faithful copy: only where it lies is wrong
        del f[obj]
        f[obj] = h5py.ExternalLink(str(foreign), "/copy")
    elif kind == "softlink":
        if variant == "moved":
            f.move(target, "/stash")
            f[target] = h5py.SoftLink("/stash")
        else:
            del f[target]
            f[target] = h5py.SoftLink("/nowhere" if variant == "dangling" else target.rsplit("/", 1)[0])
    else:  # bomb
        _bomb(f, target, arr, variant)


def _bomb(f, target: str, arr: np.ndarray, variant: str) -> None:
    """``target`` grown along its first axis to declare :data:`BOMB_BYTES` of zeros in a few stored bytes."""
    row = max(1, int(np.prod(arr.shape[1:])) * arr.dtype.itemsize)
    rows = -(-BOMB_BYTES // row)
    per_chunk = max(1, min(rows, (8 << 20) // row))
    shape, chunks = (rows, *arr.shape[1:]), (per_chunk, *arr.shape[1:])
    del f[target]
    if variant == "sparse":
        f.create_dataset(target, shape=shape, dtype=arr.dtype, chunks=chunks)
        return
    ds = f.create_dataset(target, shape=shape, dtype=arr.dtype, chunks=chunks, compression=variant)
    ds[:per_chunk] = 0
    zero = (0,) * (len(shape) - 1)
    _, raw = ds.id.read_direct_chunk((0, *zero))
    for start in range(per_chunk, rows, per_chunk):  # the one compressed chunk, repeated
        ds.id.write_direct_chunk((start, *zero), raw)


def _mutate_attr(obj, spec: dict[str, Any]) -> None:
    name, value = spec["attr"], _unjson(spec["value"])
    if isinstance(value, str) and value == "delete":
        if name in obj.attrs:
            del obj.attrs[name]
        return
    if spec["kind"] == "index":
        old = int(np.asarray(obj.attrs[name]).ravel()[0])
        value = {"minus_one": old - 1, "plus_one": old + 1, "zero": 0, "double": 2 * old}[value]
    obj.attrs[name] = value


def _where(arr: np.ndarray, spec: dict[str, Any]) -> Any:
    """Index of the elements a value or index mutation changes: one, a row, or all."""
    if arr.ndim == 0 or arr.size == 0:
        return ()
    at = spec["at"]
    scope = spec.get("scope", "one")
    if scope == "all":
        return ...
    if scope == "row":
        return at % arr.shape[0]
    return np.unravel_index(at % arr.size, arr.shape)


def _new_value(arr: np.ndarray, spec: dict[str, Any]) -> np.ndarray:
    arr = arr.copy()
    value = _unjson(spec["value"])
    if arr.dtype.kind in "iub":
        info = np.iinfo(arr.dtype) if arr.dtype.kind != "b" else None
        value = int(value) if info is None else int(np.clip(value, info.min, info.max))
    arr[_where(arr, spec)] = value
    return arr


def _new_index(arr: np.ndarray, spec: dict[str, Any]) -> np.ndarray:
    arr = arr.copy()
    op, flat = spec["op"], arr.reshape(-1)
    if arr.size == 0:
        return arr
    i = spec["at"] % arr.size
    top = int(np.iinfo(arr.dtype).max)
    if op == "minus_one":
        flat[i] = -1 if arr.dtype.kind == "i" else top
    elif op == "past_end":
        flat[i] = min(int(flat.max()) + 1, top)
    elif op == "int_max":
        flat[i] = top
    elif op == "zero":
        flat[:] = 0
    elif op == "reverse":
        flat[:] = flat[::-1].copy()
    elif op == "shuffle":
        flat[:] = np.random.default_rng(spec["at"]).permutation(flat)
    elif op == "plus_one":
        flat[:] = np.minimum(flat.astype(np.int64) + 1, top)
    elif op == "swap_last" and arr.ndim >= 2:
        arr = (
            np.ascontiguousarray(np.swapaxes(arr, -1, -2))
            if arr.shape[-1] == arr.shape[-2]
            else np.ascontiguousarray(arr[..., ::-1])
        )
    return arr


def _new_shape(arr: np.ndarray, spec: dict[str, Any]) -> np.ndarray | None:
    op = spec["op"]
    if op == "delete":
        return None
    if arr.ndim == 0:
        return np.asarray([arr, arr]) if op != "scalar" else arr
    axis = spec["axis"] % arr.ndim
    if op == "drop_last":
        return np.take(arr, range(arr.shape[axis] - 1), axis=axis)
    if op == "add_one":
        return (
            np.concatenate([arr, np.take(arr, [-1] if arr.shape[axis] else [], axis=axis)], axis=axis)
            if arr.shape[axis]
            else arr
        )
    if op == "transpose":
        return np.ascontiguousarray(arr.T)
    if op == "flatten":
        return arr.reshape(-1)
    if op == "lead_axis":
        return arr[None]
    if op == "empty":
        return np.take(arr, [], axis=axis)
    return arr.reshape(-1)[:1].reshape(()) if arr.size else np.zeros((), arr.dtype)


def _new_dtype(arr: np.ndarray, spec: dict[str, Any]) -> np.ndarray:
    dt = np.dtype(spec["dtype"])
    if dt.kind == "S":
        return np.char.mod("%s", arr).astype(dt) if arr.dtype.kind != "S" else arr.astype(dt)
    if arr.dtype.kind == "S":
        return np.zeros(arr.shape, dt)
    return arr.astype(dt)


# -- one mutant, in the worker ----------------------------------------------------------------
def check_frames(frames: list[np.ndarray]) -> dict[str, bool]:
    """Whether rendered frames are flat (every frame one value) or frozen (all frames equal)."""
    flat = all(int(f.min()) == int(f.max()) for f in frames)
    frozen = len(frames) > 1 and all(np.array_equal(frames[0], f) for f in frames[1:])
    return {"flat": flat, "frozen": frozen}


def run_mutant(path: str, mode: str, devices: list[str | None]) -> dict[str, Any]:
    """``info`` then a short render per backend; every step's outcome (never raises)."""
    from dynatex.commands.info import describe

    steps: dict[str, Any] = {"info": _attempt(describe, path)}
    for device in devices:
        key = "numpy" if device is None else f"opencl:{device}"
        steps[key] = _attempt(_render, path, mode, device)
    return steps


def _render(path: str, mode: str, device: str | None) -> dict[str, bool]:
    from dynatex.player import open_player

    opts = dict(MODE_OPTIONS.get(mode, {}))
    backend = "numpy" if device is None else "opencl"
    with open_player(path, None, mode=mode, backend=backend, device=device, seed=1, **opts) as p:
        return check_frames([p.next_frame() for _ in range(FRAMES)])


def _attempt(fn, *args) -> dict[str, Any]:
    """``fn(*args)``'s outcome: what it returned (a render's frame checks), or what it raised."""
    from dynatex.tiledb import DynatexError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = fn(*args)
    except Exception as exc:  # the whole point: classify whatever escapes
        import traceback

        tb = traceback.extract_tb(exc.__traceback__)
        where = f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else "?"
        message = str(exc)
        clean = isinstance(exc, DynatexError) and "\n" not in message and bool(message)
        return {
            "outcome": "rejected" if clean else "error",
            "type": type(exc).__name__,
            "message": message[:300],
            "where": where,
        }
    return {"outcome": "ok", "frames": result} if isinstance(result, dict) and "flat" in result else {"outcome": "ok"}


def worker_main() -> None:
    """Read ``{"path", "mode", "devices"}`` lines on stdin; answer one JSON line each."""
    proto = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)  # compiler logs and prints go to stderr, never into the protocol
    for line in sys.stdin:
        job = json.loads(line)
        if job.get("die") == "signal":  # the runner's own test: a worker that crashes...
            os.kill(os.getpid(), signal.SIGSEGV)
        if job.get("die") == "hang":  # ... and one that never answers
            time.sleep(3600)
        made = _attempt(apply, job["spec"], job["base"], job["path"]) if "spec" in job else {"outcome": "ok"}
        if made["outcome"] != "ok":
            steps = {"mutate": dict(made, outcome="error")}  # a fault of the mutator: reported, never hidden
        else:
            steps = run_mutant(job["path"], job["mode"], job["devices"])
        proto.write(json.dumps({"steps": steps, "rss": peak_rss()}) + "\n")
        proto.flush()


def peak_rss() -> dict[str, int]:
    """Peak resident bytes of this process and of its largest finished child (the probes) so far."""
    import resource

    scale = 1 if sys.platform == "darwin" else 1024
    return {
        "self": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale,
        "children": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * scale,
    }


# -- the parent's side ------------------------------------------------------------------------
@dataclass
class Result:
    spec: dict[str, Any]
    outcome: str
    steps: dict[str, Any] = field(default_factory=dict)
    rss: dict[str, int] = field(default_factory=dict)

    def line(self) -> str:
        detail = {k: v for k, v in self.steps.items() if isinstance(v, dict) and v.get("outcome") not in ("ok",)}
        return f"{self.outcome}: {json.dumps(self.spec)} {json.dumps(detail)[:600]}"


class Runner:
    """Runs mutants in worker processes with a per-mutant timeout; see the module docstring."""

    def __init__(
        self,
        bases: dict[str, Path],
        folder: str | os.PathLike,
        *,
        devices: list[str | None],
        timeout: float = 60.0,
        workers: int = 1,
        max_bytes: int | None = None,
    ) -> None:
        """``max_bytes``: the workers' bound on declared bytes per read (``DYNATEX_MAX_READ_BYTES``)."""
        self.max_bytes = max_bytes
        self.bases = bases
        self.folder = Path(folder)
        self.devices = devices
        self.timeout = timeout
        self.nworkers = workers
        self.inventories = {m: inventory(p) for m, p in bases.items()}
        self.controls: dict[str, dict[str, Any]] = {}
        self.control_rss: dict[str, dict[str, int]] = {}
        self._log = open(self.folder / "workers.log", "ab")

    def control(self, method: str) -> dict[str, Any]:
        """Steps of the unmutated database of ``method`` (rendered once, cached)."""
        if method not in self.controls:
            res = self._run_all(
                [{"path": str(self.bases[method]), "mode": METHOD_MODES[method], "devices": self.devices}],
                [{"method": method, "kind": "control"}],
            )
            self.controls[method] = res[0].steps
            self.control_rss[method] = res[0].rss
        return self.controls[method]

    def baseline_rss(self) -> int:
        """Peak resident memory of the workers after the controls: the interpreter, the OpenCL
        runtimes (Intel's alone is hundreds of MiB) and the unmutated models, which a mutant's
        peak is measured against rather than against a figure of one machine's drivers."""
        return max((max(r.get("self", 0), r.get("children", 0)) for r in self.control_rss.values()), default=0)

    def run(self, seed: int, indices: Iterable[int], *, structural: bool = False) -> list[Result]:
        """Mutants ``indices`` of ``seed``: byte and value mutations, or the structural ones."""
        specs = [(plan_structural if structural else plan)(seed, i, self.inventories) for i in indices]
        for method in {s["method"] for s in specs}:
            self.control(method)
        jobs = [
            {
                "spec": spec,
                "base": str(self.bases[spec["method"]]),
                "mode": METHOD_MODES[spec["method"]],
                "devices": self.devices,
            }
            for spec in specs
        ]
        return self._run_all(jobs, specs)

    # Each worker writes its mutants to a file of its own (``mutant-wN.h5``).
    def _run_all(self, jobs: list[dict], specs: list[dict]) -> list[Result]:
        results: list[Result | None] = [None] * len(jobs)
        pending = list(range(len(jobs)))[::-1]
        workers: list[_Worker | None] = [None] * self.nworkers
        busy: dict[int, tuple[int, float]] = {}
        while pending or busy:
            for w in range(self.nworkers):
                if w not in busy and pending:
                    j = pending.pop()
                    if "spec" in jobs[j]:
                        jobs[j] = dict(jobs[j], path=str(self.folder / f"mutant-w{w}.h5"))
                    if workers[w] is None or not workers[w].alive():
                        workers[w] = _Worker(self._log, self.max_bytes)
                    workers[w].send(jobs[j])
                    busy[w] = (j, time.monotonic() + self.timeout)
            ready = _Worker.wait([workers[w] for w in busy], min(d for _, d in busy.values()) - time.monotonic())
            now = time.monotonic()
            for w in list(busy):
                j, deadline = busy[w]
                worker = workers[w]
                if worker in ready:
                    answer = worker.receive()
                    if answer is None:  # died
                        code = worker.close()
                        workers[w] = None
                        results[j] = Result(specs[j], "crash", {"exit": code})
                    else:
                        steps = answer["steps"]
                        results[j] = Result(specs[j], self._classify(specs[j], steps), steps, answer["rss"])
                    del busy[w]
                elif now >= deadline:
                    worker.kill()
                    workers[w] = None
                    results[j] = Result(specs[j], "hang", {"timeout_s": self.timeout})
                    del busy[w]
        for worker in workers:
            if worker is not None:
                worker.close()
        return results  # type: ignore[return-value]

    def _classify(self, spec: dict[str, Any], steps: dict[str, Any]) -> str:
        outcomes = []
        control = self.controls.get(spec["method"]) if spec.get("kind") != "control" else None
        for key, step in steps.items():
            outcome = step["outcome"]
            if outcome == "ok" and control is not None and key != "info":
                ref = control[key].get("frames", {})
                got = step["frames"]
                if (got["flat"] and not ref.get("flat")) or (got["frozen"] and not ref.get("frozen")):
                    outcome = "garbage"
            if outcome in ("ok", "garbage") and spec.get("kind") in LINKS:
                outcome = "foreign"
            outcomes.append(outcome)
        return max(outcomes, key=OUTCOMES.index)

    def close(self) -> None:
        self._log.close()


class _Worker:
    def __init__(self, log, max_bytes: int | None = None) -> None:
        env = dict(os.environ, PYTHONWARNINGS="ignore")
        if max_bytes is not None:
            env["DYNATEX_MAX_READ_BYTES"] = str(max_bytes)
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=log,
            env=env,
            start_new_session=True,
        )
        self._buf = b""

    def fileno(self) -> int:
        return self.proc.stdout.fileno()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def send(self, job: dict) -> None:
        try:
            self.proc.stdin.write((json.dumps(job) + "\n").encode())
            self.proc.stdin.flush()
        except BrokenPipeError:
            pass  # it died; receive() reports it

    @staticmethod
    def wait(workers: list[_Worker], timeout: float) -> list[_Worker]:
        ready, _, _ = select.select(workers, [], [], max(0.0, timeout))
        return ready

    def receive(self) -> dict | None:
        """The answer to the job sent, or None when the worker died instead."""
        while b"\n" not in self._buf:
            chunk = os.read(self.fileno(), 1 << 16)
            if not chunk:
                return None
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        return json.loads(line)

    def kill(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.close()

    def close(self) -> int | None:
        for f in (self.proc.stdin, self.proc.stdout):
            try:
                f.close()
            except OSError:
                pass
        try:
            return self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            return self.proc.wait()


def verified_device() -> list[str | None]:
    """Backends a mutant renders on: numpy, and the first verified OpenCL device if any."""
    from dynatex.player.opencl import context as opencl
    from dynatex.player.opencl import verify

    try:
        infos = opencl.preference_order(opencl.devices())
    except opencl.OpenCLUnavailableError:
        return [None]
    ok = [d for d in infos if verify.verdict(d).ok]
    return [None] + ([ok[0].index] if ok else [])


def table(results: list[Result], key: str = "method") -> str:
    """Outcome counts per ``key`` (``method`` or ``variant``) and mutation kind, as a Markdown table."""
    rows: dict[tuple[str, str], dict[str, int]] = {}
    for r in results:
        row = rows.setdefault((r.spec.get(key, "-"), r.spec["kind"]), dict.fromkeys(OUTCOMES, 0))
        row[r.outcome] += 1
    lines = [f"| {key} | mutation | " + " | ".join(OUTCOMES) + " | total |", "|---" * (len(OUTCOMES) + 3) + "|"]
    total = dict.fromkeys(OUTCOMES, 0)
    for (method, kind), row in sorted(rows.items()):
        lines.append(
            f"| {method} | {kind} | " + " | ".join(str(row[o]) for o in OUTCOMES) + f" | {sum(row.values())} |"
        )
        for o in OUTCOMES:
            total[o] += row[o]
    lines.append("| **all** | | " + " | ".join(f"**{total[o]}**" for o in OUTCOMES) + f" | **{sum(total.values())}** |")
    return "\n".join(lines)


def fuzz(
    bases: dict[str, Path],
    folder: str | os.PathLike,
    *,
    seed: int,
    count: int,
    start: int = 0,
    timeout: float = 60.0,
    workers: int = 1,
    devices: list[str | None] | None = None,
    structural: bool = False,
    max_bytes: int | None = None,
) -> Iterator[Result]:
    """Run mutants ``start .. start + count - 1`` of ``seed`` (the structural ones with
    ``structural``); yields results in order."""
    runner = Runner(
        bases,
        folder,
        devices=verified_device() if devices is None else devices,
        timeout=timeout,
        workers=workers,
        max_bytes=max_bytes,
    )
    try:
        step = 50
        for lo in range(start, start + count, step):
            yield from runner.run(seed, range(lo, min(lo + step, start + count)), structural=structural)
    finally:
        runner.close()


if __name__ == "__main__" and "--worker" in sys.argv:
    worker_main()
elif __name__ == "__main__":
    sys.exit("run through tools/fuzz_databases.py or tests/tiledb/test_fuzz.py")
