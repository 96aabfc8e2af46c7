"""Reading clips: a video file (OpenCV), a folder of images, or a numpy array.

Frames come out as ``(T, H, W, C)`` uint8 in RGB order (``C = 3``) or grey (``C = 1``).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import KW_ONLY, dataclass, fields
from typing import Any

import numpy as np

from ..checks import MAX_SIDE, check_frames, check_int, check_size
from ..child import Outcome, call
from ..errors import InvalidArgumentError
from ..stale import hold, release, remove_unheld
from ..tiledb import SourceInfo
from .errors import ClipError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm")

#: Scratch space of a run: decode folders and ``--max-memory`` spill files, named like ``tempfile``'s.
SCRATCH_PATTERN = re.compile(r"dynatex-(decode|spill)-[a-z0-9_]{8}(\.u8)?")

Progress = Callable[[int, int | None], None]
#: Seconds a child decoding a video may take before it counts as hung: this plus DECODE_S_PER_MB per
#: MB of file.
DECODE_TIMEOUT_S = 120.0
DECODE_S_PER_MB = 10.0


@dataclass
class ClipSource:
    """Where a clip's frames came from, as :meth:`source_info` stores it beside the models: one
    definition for :class:`Clip` (frames in memory) and :class:`~dynatex.analyzer.stream.DiskClip`
    (frames on disk), which give ``n_frames`` and ``frame_shape`` ``(H, W, C)``."""

    _: KW_ONLY
    fps: float
    filename: str
    sha256: str
    frame_start: int = 0
    frame_step: int = 1
    crop: tuple[int, ...] = ()
    source_size: tuple[int, ...] = ()  # (height, width) of the decoded source frames

    def source(self) -> dict[str, Any]:
        """These fields by name: what another clip of the same frames is made with."""
        return {f.name: getattr(self, f.name) for f in fields(ClipSource)}

    def source_info(self) -> SourceInfo:
        h, w, c = self.frame_shape
        return SourceInfo(width=w, height=h, channels=c, n_frames=self.n_frames, **self.source())


@dataclass
class Clip(ClipSource):
    """Decoded frames plus where they came from."""

    frames: np.ndarray  # (T, H, W, C) uint8

    @property
    def n_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.frames.shape[1:])  # type: ignore[return-value]

    frame_shape = shape


def load_clip(
    source: str | os.PathLike | np.ndarray,
    *,
    start: int = 0,
    stop: int | None = None,
    step: int = 1,
    crop: Sequence[int] | None = None,
    size: Sequence[int] | None = None,
    color: bool = True,
    fps: float | None = None,
    isolate: bool = False,
    progress: Progress | None = None,
) -> Clip:
    """Read a clip and return its frames as a :class:`Clip`.

    Parameters
    ----------
    source : path or ndarray
        A video file OpenCV can decode, a folder of images (sorted by name), or an array
        ``(T, H, W)`` / ``(T, H, W, 1)`` / ``(T, H, W, 3)`` (uint8, or floats on 0..255; RGB order).
    start, stop, step : int
        Frame range, as in ``range(start, stop, step)`` over the source frames.
    crop : (x, y, w, h), optional
        Region kept, in source pixels, applied before ``size``. A rectangle (corner first, as
        the command line's ``--crop X,Y,W,H`` and the file's ``crop`` attribute), not a size.
    size : (height, width), optional
        Resize every frame to this size (area interpolation).
    color : bool
        RGB frames when true, single-channel grey when false.
    fps : float, optional
        Frame rate to record (default: the file's, or 25 for images and arrays).
    isolate : bool
        Decode a video file in a child process (:func:`dynatex.child.call`), so that a decoder
        crash or hang on a hostile file becomes a :class:`ClipError` (a hang after
        :func:`decode_timeout` seconds) instead of taking down the caller.
    progress : callable(done, total), optional
        Called as frames are decoded.

    Examples
    --------
    >>> import numpy as np
    >>> clip = load_clip(np.zeros((10, 32, 48, 3), np.uint8), size=(16, 24))
    >>> clip.frames.shape
    (10, 16, 24, 3)
    """
    start = check_int("start", start, 0)
    step = check_int("step", step, 1, rule="at least 1")
    if stop is not None:
        stop = check_int("stop", stop, 0)
        if stop <= start:
            raise InvalidArgumentError(f"stop ({stop}) must be greater than start ({start})")
    crop_t = _tuple4("crop", crop) if crop is not None else None
    size_t = check_size("size", size, MAX_SIDE) if size is not None else None

    if isinstance(source, np.ndarray):
        frames = _from_array(source)[start:stop:step]
        name, digest, src_fps = "<array>", hashlib.sha256(np.ascontiguousarray(source).data).hexdigest(), 25.0
    else:
        path = os.fspath(source)
        if not os.path.exists(path):
            raise FileNotFoundError(f"{path}: no such clip file or folder")
        name = os.path.basename(os.path.normpath(path))
        if os.path.isdir(path):
            frames, digest = _from_folder(path, start, stop, step, progress)
            src_fps = 25.0
        elif isolate:
            frames, src_fps, digest = _decode_isolated(path, start, stop, step)
        else:
            frames, src_fps, digest = _from_video(path, start, stop, step, progress)
    if frames.shape[0] == 0:
        raise ClipError(f"{name}: no frames in range start={start} stop={stop} step={step}")
    if frames.shape[0] < 2:
        raise ClipError(f"{name}: only one frame in range; a dynamic texture needs at least 2")
    source_size = frames.shape[1:3]
    frames = _crop_resize_color(frames, crop_t, size_t, color, name)
    return Clip(
        frames=frames,
        fps=float(fps if fps is not None else src_fps),
        filename=name,
        sha256=digest,
        frame_start=start,
        frame_step=step,
        crop=crop_t or (),
        source_size=source_size,
    )


# -- sources ----------------------------------------------------------------------
def _from_array(arr: np.ndarray) -> np.ndarray:
    if arr.ndim == 3:
        arr = arr[..., None]
    if arr.ndim != 4 or arr.shape[-1] not in (1, 3):
        raise ClipError(f"clip array must be (T, H, W), (T, H, W, 1) or (T, H, W, 3), not {arr.shape}")
    if arr.dtype == np.uint8:
        return arr
    if arr.dtype.kind not in "fiu":
        raise ClipError(f"clip array dtype {arr.dtype} is not numeric")
    if arr.size and (not np.isfinite(arr).all() or arr.min() < 0 or arr.max() > 255):
        raise ClipError("clip array values must be finite and within 0..255")
    return np.rint(arr).astype(np.uint8)


def _file_digest(path: str, h: hashlib._Hash | None = None) -> hashlib._Hash:
    h = h or hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h


def _from_folder(path: str, start: int, stop: int | None, step: int, progress: Progress | None):
    import cv2

    names = sorted(n for n in os.listdir(path) if n.lower().endswith(IMAGE_SUFFIXES))
    if not names:
        raise ClipError(f"{path}: folder holds no images ({', '.join(IMAGE_SUFFIXES)})")
    names = names[start:stop:step]
    h = hashlib.sha256()
    frames = []
    for i, n in enumerate(names):
        full = os.path.join(path, n)
        img = cv2.imread(full, cv2.IMREAD_COLOR)
        if img is None:
            raise ClipError(f"{full}: cannot decode image")
        if frames and img.shape != frames[0].shape:
            raise ClipError(
                f"{full}: size {img.shape[1]}x{img.shape[0]} differs from the first image's "
                f"{frames[0].shape[1]}x{frames[0].shape[0]}"
            )
        _file_digest(full, h)
        frames.append(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
        if progress:
            progress(i + 1, len(names))
    return np.stack(frames) if frames else np.zeros((0, 1, 1, 3), np.uint8), h.hexdigest()


def _from_video(path: str, start: int, stop: int | None, step: int, progress: Progress | None):
    import cv2

    if os.path.getsize(path) == 0:
        raise ClipError(f"{path}: file is empty")
    cap = cv2.VideoCapture(path)
    try:
        if not cap.isOpened():
            raise ClipError(f"{path}: OpenCV cannot open it as a video")
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if not np.isfinite(fps) or fps <= 0 or fps > 1000:
            fps = 25.0
        total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0) or None
        want = None if total is None else len(range(start, total if stop is None else min(stop, total), step))
        frames = []
        index = 0
        while stop is None or index < stop:
            ok, img = cap.read()
            if not ok or img is None:
                break
            if index >= start and (index - start) % step == 0:
                if img.ndim == 2:
                    img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
                frames.append(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
                if progress:
                    progress(len(frames), want)
            index += 1
    finally:
        cap.release()
    if index == 0:
        raise ClipError(f"{path}: no frame could be decoded")
    if frames and any(f.shape != frames[0].shape for f in frames):
        raise ClipError(f"{path}: frame size changes within the clip")
    out = np.stack(frames) if frames else np.zeros((0, 1, 1, 3), np.uint8)
    return out, fps, _file_digest(path).hexdigest()


def _decode_to(path: str, start: int, stop: int | None, step: int, out_npy: str) -> list:
    """The decoding child's work (:func:`_decode_isolated`): the frames saved to ``out_npy``;
    returns ``[fps, sha256]``."""
    frames, fps, digest = _from_video(path, start, stop, step, None)
    np.save(out_npy, frames)
    return [fps, digest]


# -- scratch space ---------------------------------------------------------------------
def remove_stale_scratch(folder: str | None = None) -> list[str]:
    """Remove the decode folders and spill files that killed runs left in ``folder`` (default: the
    temporary folder): those named by :data:`SCRATCH_PATTERN` that no live run holds a lock on."""
    return remove_unheld(folder or tempfile.gettempdir(), SCRATCH_PATTERN, folders=True)


@contextlib.contextmanager
def scratch_folder(prefix: str = "dynatex-decode-") -> Iterator[str]:
    """A new folder in the temporary folder, held (:func:`dynatex.stale.hold`) and removed on every
    way out; stale ones of killed runs are removed first."""
    remove_stale_scratch()
    tmp, fd = None, None
    try:
        while fd is None:
            tmp = tempfile.mkdtemp(prefix=prefix)
            fd = hold(tmp)
        yield tmp
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        release(fd)


def _decode_isolated(path: str, start: int, stop: int | None, step: int):
    with scratch_folder() as tmp:
        out = os.path.join(tmp, "frames.npy")
        child = call(f"{__name__}:_decode_to", path, start, stop, step, out, timeout=decode_timeout(path))
        if not child.ok:
            raise decoder_error(path, child)
        frames = np.load(out, allow_pickle=False)
    fps, digest = child.value
    return frames, float(fps), digest


def decode_timeout(path: str) -> float:
    """Seconds a child decoding ``path`` may take before it counts as hung (:data:`DECODE_TIMEOUT_S`
    plus :data:`DECODE_S_PER_MB` per MB of file)."""
    return DECODE_TIMEOUT_S + DECODE_S_PER_MB * os.path.getsize(path) / 2**20


def decoder_error(path: str, child: Outcome) -> Exception:
    """The error for a decoding child that failed: what it raised (a ``FileNotFoundError`` stays
    one, anything else becomes a :class:`ClipError`), else a :class:`ClipError` saying how the
    decoder ended (a crash, a hang, no memory)."""
    if child.raised is not None:
        kind, message = child.raised
        return (FileNotFoundError if kind == "FileNotFoundError" else ClipError)(message)
    return ClipError(
        f"{path}: the video decoder {child.describe()}; re-encode the clip (for example to FFV1 or H.264) and try again"
    )


# -- geometry -----------------------------------------------------------------------
def _crop_resize_color(frames: np.ndarray, crop, size, color: bool, name: str) -> np.ndarray:
    t, h, w, c = frames.shape
    if crop is not None:
        x, y, cw, ch = crop
        if cw < 1 or ch < 1 or x + cw > w or y + ch > h:
            raise InvalidArgumentError(f"crop {crop} does not fit the {w}x{h} frames of {name}")
        frames = frames[:, y : y + ch, x : x + cw]
    if size is not None and frames.shape[1:3] != tuple(size):
        import cv2

        out = np.empty((t, size[0], size[1], c), np.uint8)
        for i in range(t):
            r = cv2.resize(frames[i], (size[1], size[0]), interpolation=cv2.INTER_AREA)  # cv2 takes (w, h)
            out[i] = r.reshape(out.shape[1:])
        frames = out
    if color and frames.shape[-1] == 1:
        frames = np.repeat(frames, 3, axis=-1)
    elif not color and frames.shape[-1] == 3:
        import cv2

        grey = np.empty(frames.shape[:3] + (1,), np.uint8)
        for i in range(t):
            grey[i, ..., 0] = cv2.cvtColor(np.ascontiguousarray(frames[i]), cv2.COLOR_RGB2GRAY)
        frames = grey
    return np.ascontiguousarray(frames)


def _tuple4(name: str, v) -> tuple[int, int, int, int]:
    try:
        t = tuple(int(x) for x in v)
    except (TypeError, ValueError):
        raise InvalidArgumentError(f"{name} must be four integers (x, y, w, h), not {v!r}") from None
    if len(t) != 4 or min(t) < 0:
        raise InvalidArgumentError(f"{name} must be four non-negative integers (x, y, w, h), not {v!r}")
    return t  # type: ignore[return-value]


def clip_frames(clip: Any) -> np.ndarray:
    """The ``(T, H, W, C)`` uint8 frames of a :class:`Clip` or an array, else an error naming "clip"."""
    return check_frames(clip.frames if isinstance(clip, Clip) else clip, name="clip", uint8=True)


def load_clip_path(path: str, *, isolate: bool = True, **options) -> Clip:
    """:func:`load_clip` of a clip named by a path: a ``.npy`` file is read as an array (no
    pickles, see :func:`load_npy`); a video file is decoded in a child process when ``isolate``
    (a decoder crash becomes a :class:`ClipError`); a folder of images is read in this process."""
    if path.endswith(".npy") and os.path.isfile(path):
        return load_clip(load_npy(path), **options)
    return load_clip(path, isolate=isolate and os.path.isfile(path), **options)


def npy_header(path: str) -> tuple[tuple[int, ...], bool, np.dtype, int]:
    """``(shape, fortran_order, dtype, data offset)`` of a ``.npy`` clip, or a :class:`ClipError`
    naming the file when it cannot hold frames: not a ``.npy`` array, Python objects (a pickle),
    not 3 or 4 dimensions, an empty dimension, or shorter than its header says."""
    name = os.path.basename(path)
    with open(path, "rb") as f:
        try:
            version = np.lib.format.read_magic(f)
            reader = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, fortran, dtype = reader(f)
        except (ValueError, OSError, SyntaxError) as exc:
            raise ClipError(f"{name}: not a readable .npy array ({_one_line(exc)})") from None
        offset = f.tell()
    if dtype.hasobject:
        raise ClipError(f"{name}: holds Python objects (a pickle), not frames; save uint8 frames (T, H, W[, C])")
    if len(shape) not in (3, 4) or (len(shape) == 4 and shape[3] not in (1, 3)):
        raise ClipError(f"{name}: array of shape {shape} is not frames (T, H, W), (T, H, W, 1) or (T, H, W, 3)")
    if 0 in shape:
        raise ClipError(f"{name}: array of shape {shape} has an empty dimension")
    need = offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if os.path.getsize(path) < need:
        raise ClipError(f"{name}: file is truncated ({os.path.getsize(path)} bytes, its {shape} header needs {need})")
    return tuple(shape), bool(fortran), dtype, offset


def load_npy(path: str, mmap_mode: str | None = None) -> np.ndarray:
    """A ``.npy`` clip's array (checked by :func:`npy_header` first; never unpickled)."""
    npy_header(path)
    try:
        return np.load(path, mmap_mode=mmap_mode, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise ClipError(f"{os.path.basename(path)}: not a readable .npy array ({_one_line(exc)})") from None


def _one_line(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__
