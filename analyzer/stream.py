"""Clips larger than memory: frames spilled to (or read from) a raw on-disk array.

A :class:`DiskClip` holds no frames in memory. Learning reads it either by frame ranges
or by pixel columns (every frame's values of a block of pixels), which is what the
out-of-core SVD of :func:`~dynatex.analyzer.lds.learn_lds` needs: the ``T x T`` Gram
matrix of the mean-subtracted clip is a sum over pixel blocks.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from .. import stale
from ..checks import check_size
from ..child import call
from ..errors import InvalidArgumentError
from .video import (
    IMAGE_SUFFIXES,
    MAX_SIDE,
    ClipError,
    ClipSource,
    Progress,
    _crop_resize_color,
    _tuple4,
    decode_timeout,
    decoder_error,
    load_npy,
    npy_header,
    remove_stale_scratch,
)

_UNITS = {
    "": 1,
    "B": 1,
    "K": 1 << 10,
    "KB": 1 << 10,
    "M": 1 << 20,
    "MB": 1 << 20,
    "G": 1 << 30,
    "GB": 1 << 30,
    "T": 1 << 40,
    "TB": 1 << 40,
    "KIB": 1 << 10,
    "MIB": 1 << 20,
    "GIB": 1 << 30,
    "TIB": 1 << 40,
}


def parse_bytes(text: str | int) -> int:
    """``"2GB"``, ``"512M"``, ``"1.5GiB"`` or a plain number of bytes -> bytes (binary units).

    Examples
    --------
    >>> parse_bytes("2GB"), parse_bytes("512m"), parse_bytes(1024)
    (2147483648, 536870912, 1024)
    """
    if isinstance(text, (int, np.integer)) and not isinstance(text, bool):
        value = float(text)
    else:
        s = str(text).strip().upper().replace(" ", "")
        num = s.rstrip("KMGTIB")
        unit = s[len(num) :]
        if unit not in _UNITS:
            raise InvalidArgumentError(
                f"memory size {text!r} is not a number of bytes with a unit such as 512MB or 2GB"
            )
        try:
            value = float(num) * _UNITS[unit]
        except ValueError:
            raise InvalidArgumentError(
                f"memory size {text!r} is not a number of bytes with a unit such as 512MB or 2GB"
            ) from None
    if not np.isfinite(value) or value < 1:
        raise InvalidArgumentError(f"memory size {text!r} must be positive")
    return int(value)


@dataclass
class DiskClip(ClipSource):
    """Frames ``(T, H, W, C)`` uint8 stored row-major in a file at ``offset``, plus their source description.

    ``owned`` clips (spilled by :func:`spill_clip`) delete their file on :meth:`close`.
    """

    path: str
    offset: int
    frame_shape: tuple[int, int, int]
    n_frames: int
    owned: bool = False
    hold: int | None = field(default=None, repr=False)  # the lock that marks an owned file live

    @property
    def pixels(self) -> int:
        h, w, c = self.frame_shape
        return h * w * c

    @property
    def nbytes(self) -> int:
        return self.n_frames * self.pixels

    def frames(self, t0: int = 0, t1: int | None = None) -> np.ndarray:
        """Frames ``t0:t1`` read into memory, ``(t1 - t0, H, W, C)`` uint8."""
        t1 = self.n_frames if t1 is None else t1
        out = np.empty((t1 - t0,) + self.frame_shape, np.uint8)
        with open(self.path, "rb") as f:
            f.seek(self.offset + t0 * self.pixels)
            if f.readinto(memoryview(out).cast("B")) != out.nbytes:
                raise ClipError(f"{self.path}: frame file is shorter than {self.n_frames} frames")
        return out

    def columns(self, p0: int, p1: int, out: np.ndarray | None = None) -> np.ndarray:
        """Values ``p0:p1`` of every frame, ``(T, p1 - p0)`` uint8: one read per frame."""
        width = p1 - p0
        if out is None:
            out = np.empty((self.n_frames, width), np.uint8)
        fd = os.open(self.path, os.O_RDONLY)
        try:
            for t in range(self.n_frames):
                view = memoryview(out[t, :width]).cast("B")
                if os.preadv(fd, [view], self.offset + t * self.pixels + p0) != width:
                    raise ClipError(f"{self.path}: frame file is shorter than {self.n_frames} frames")
        finally:
            os.close(fd)
        return out[:, :width]

    def close(self) -> None:
        """Delete the spill file of an owned clip."""
        if self.owned and os.path.exists(self.path):
            os.unlink(self.path)
        stale.release(self.hold)
        self.hold = None

    def __enter__(self) -> DiskClip:  # noqa: PYI034
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def spill_clip(
    source: str | os.PathLike,
    *,
    folder: str | None = None,
    start: int = 0,
    stop: int | None = None,
    step: int = 1,
    crop: Sequence[int] | None = None,
    size: Sequence[int] | None = None,
    color: bool = True,
    fps: float | None = None,
    isolate: bool = False,
    progress: Progress | None = None,
) -> DiskClip:
    """Decode a clip frame by frame into a raw file, never holding more than one frame.

    Same sources and options as :func:`~dynatex.analyzer.load_clip`, with the same
    ``sha256`` (so a database learned either way describes its source the same). A
    ``.npy`` array of uint8 frames with no frame range or geometry options is read where
    it lies. ``folder`` holds the spill file (default: the system's temporary folder);
    ``isolate`` decodes in a child process so a decoder crash becomes a :class:`ClipError`.
    """
    path = os.fspath(source)
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path}: no such clip file or folder")
    crop_t = _tuple4("crop", crop) if crop is not None else None
    size_t = check_size("size", size, MAX_SIDE) if size is not None else None
    plain = start == 0 and stop is None and step == 1 and crop_t is None and size_t is None
    if path.endswith(".npy") and os.path.isfile(path):
        direct = _npy_direct(path, color, fps)
        if direct is not None and plain:
            return direct
    remove_stale_scratch(folder)
    hold, out = None, None
    try:
        while hold is None:
            fd, out = tempfile.mkstemp(prefix="dynatex-spill-", suffix=".u8", dir=folder)
            os.close(fd)
            hold = stale.hold(out)
        if isolate and os.path.isfile(path) and not path.endswith(".npy"):
            meta = _spill_isolated(path, out, start, stop, step, crop_t, size_t, color)
        else:
            meta = _spill(path, out, start, stop, step, crop_t, size_t, color, progress)
    except BaseException:
        if out is not None and os.path.exists(out):
            os.unlink(out)
        stale.release(hold)
        raise
    shape, n, src_fps, digest, source_size = meta
    return DiskClip(
        path=out,
        offset=0,
        frame_shape=shape,
        n_frames=n,
        fps=float(fps or src_fps),
        filename=os.path.basename(os.path.normpath(path)),
        sha256=digest,
        frame_start=start,
        frame_step=step,
        crop=crop_t or (),
        source_size=source_size,
        owned=True,
        hold=hold,
    )


def _npy_direct(path: str, color: bool, fps: float | None) -> DiskClip | None:
    shape, fortran, dtype, offset = npy_header(path)
    if dtype != np.uint8 or fortran or len(shape) not in (3, 4):
        return None
    channels = 1 if len(shape) == 3 else shape[3]
    if channels not in (1, 3) or (channels == 3) != color:
        return None
    n = shape[0]
    if n < 2:
        raise ClipError(f"{os.path.basename(path)}: only {n} frame(s); a dynamic texture needs at least 2")
    frame_shape = (shape[1], shape[2], channels)
    if os.path.getsize(path) < offset + n * int(np.prod(frame_shape)):
        raise ClipError(f"{path}: file is truncated (shorter than its {shape} header says)")
    h = hashlib.sha256()
    with open(path, "rb") as f:
        f.seek(offset)
        for block in iter(lambda: f.read(1 << 22), b""):
            h.update(block)
    return DiskClip(
        path=os.path.abspath(path),
        offset=offset,
        frame_shape=frame_shape,
        n_frames=n,
        fps=float(fps or 25.0),
        filename=os.path.basename(path),
        sha256=h.hexdigest(),
        source_size=(shape[1], shape[2]),
    )


def _spill(path, out, start, stop, step, crop, size, color, progress):
    name = os.path.basename(os.path.normpath(path))
    n = 0
    shape = None
    source_size = ()
    with open(out, "wb") as f:
        frames, src_fps, digest = _frame_source(path, start, stop, step)
        for frame in frames:
            if shape is None:
                source_size = frame.shape[:2]
            one = _crop_resize_color(frame[None], crop, size, color, name)[0]
            if shape is None:
                shape = one.shape
            elif one.shape != shape:
                raise ClipError(f"{path}: frame size changes within the clip")
            f.write(one.tobytes())
            n += 1
            if progress:
                progress(n, None)
    if n < 2:
        raise ClipError(
            f"{name}: {'no frames' if n == 0 else 'only one frame'} in range start={start} "
            f"stop={stop} step={step}; a dynamic texture needs at least 2"
        )
    return tuple(shape), n, src_fps, digest(), tuple(source_size)


def _frame_source(path: str, start: int, stop: int | None, step: int):
    """(iterator of RGB frames in range, fps, callable giving the sha256 once the iterator is spent)."""
    from .video import _file_digest

    if os.path.isdir(path):
        names = sorted(n for n in os.listdir(path) if n.lower().endswith(IMAGE_SUFFIXES))
        if not names:
            raise ClipError(f"{path}: folder holds no images ({', '.join(IMAGE_SUFFIXES)})")
        names = names[start:stop:step]
        h = hashlib.sha256()
        return _images(path, names, h), 25.0, h.hexdigest
    if path.endswith(".npy"):
        arr = load_npy(path, mmap_mode="r")
        from .video import _from_array

        digest = hashlib.sha256()

        def gen() -> Iterator[np.ndarray]:
            for i in range(arr.shape[0]):
                digest.update(np.ascontiguousarray(arr[i]).data)
            for i in range(start, arr.shape[0] if stop is None else min(stop, arr.shape[0]), step):
                one = _from_array(np.asarray(arr[i : i + 1]))[0]
                yield one if one.shape[-1] == 3 else np.repeat(one, 3, axis=-1)

        return gen(), 25.0, digest.hexdigest
    if os.path.getsize(path) == 0:
        raise ClipError(f"{path}: file is empty")
    frames, fps = _video_frames(path, start, stop, step)
    return frames, fps, lambda: _file_digest(path).hexdigest()


def _images(folder: str, names: list[str], h) -> Iterator[np.ndarray]:
    import cv2

    from .video import _file_digest

    for n in names:
        full = os.path.join(folder, n)
        img = cv2.imread(full, cv2.IMREAD_COLOR)
        if img is None:
            raise ClipError(f"{full}: cannot decode image")
        _file_digest(full, h)
        yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _video_frames(path: str, start: int, stop: int | None, step: int):
    import cv2

    cap = cv2.VideoCapture(path)
    if not cap.isOpened():
        cap.release()
        raise ClipError(f"{path}: OpenCV cannot open it as a video")
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    if not np.isfinite(fps) or fps <= 0 or fps > 1000:
        fps = 25.0

    def gen() -> Iterator[np.ndarray]:
        index = 0
        try:
            while stop is None or index < stop:
                ok, img = cap.read()
                if not ok or img is None:
                    break
                if index >= start and (index - start) % step == 0:
                    if img.ndim == 2:
                        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
                    yield cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
                index += 1
        finally:
            cap.release()
        if index == 0:
            raise ClipError(f"{path}: no frame could be decoded")

    return gen(), fps


def _spill_isolated(path, out, start, stop, step, crop, size, color):
    child = call(f"{__name__}:_spill_to", path, out, start, stop, step, crop, size, color, timeout=decode_timeout(path))
    if not child.ok:
        raise decoder_error(path, child)
    shape, n, fps, digest, source_size = child.value
    return tuple(shape), n, fps, digest, tuple(source_size)


def _spill_to(path, out, start, stop, step, crop, size, color) -> tuple:
    """The spilling child's work (:func:`_spill_isolated`): the frames written into ``out``;
    returns their description."""
    return _spill(path, out, start, stop, step, crop and tuple(crop), size and tuple(size), color, None)
