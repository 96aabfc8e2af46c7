"""OpenCL devices: the devices present, device choice (only devices that passed the
self-test, :mod:`dynatex.player.opencl.verify`) and one context per device.
"""

from __future__ import annotations

import logging
import os
import re
import threading
from dataclasses import dataclass

from ..errors import DeviceNotVerifiedError, OpenCLUnavailableError

try:
    import pyopencl as cl
except ImportError as _exc:  # pragma: no cover - pyopencl is a hard dependency
    cl = None
    _IMPORT_ERROR: Exception | None = _exc
else:
    _IMPORT_ERROR = None

log = logging.getLogger(__name__)

#: the numpy backend, as the API and the command line spell it
_NUMPY = "use the numpy backend (backend='numpy'; dynatex --backend numpy)"
_FIX = f"install an OpenCL platform (./install.sh, or `apt-get install pocl-opencl-icd`), or {_NUMPY}"


_lock = threading.Lock()
_contexts: dict[str, cl.Context] = {}
_infos: dict[int, DeviceInfo] = {}  # device handle -> its DeviceInfo, for get_context's devices


@dataclass(frozen=True)
class DeviceInfo:
    """What identifies one OpenCL device: its ``P:D`` index and the names its verdict is cached by."""

    index: str
    platform: str
    platform_version: str
    name: str
    vendor: str
    driver_version: str
    is_cpu: bool

    @property
    def is_pocl(self) -> bool:
        return "portable computing language" in self.platform.lower() or "pocl" in self.platform_version.lower()

    def describe(self) -> str:
        """One line: platform, version, device."""
        return f"{self.platform} ({' '.join(self.platform_version.split()[:4])}) / {self.name}"


def devices() -> list[DeviceInfo]:
    """Every OpenCL device present, in ``PYOPENCL_CTX`` index order (none without OpenCL)."""
    _require_pyopencl()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    out = []
    for i, p in enumerate(platforms):
        try:
            devs = p.get_devices()
        except cl.Error:
            continue
        for j, d in enumerate(devs):
            out.append(
                DeviceInfo(
                    f"{i}:{j}",
                    p.name.strip(),
                    p.version.strip(),
                    d.name.strip(),
                    d.vendor.strip(),
                    d.driver_version.strip(),
                    bool(d.type & cl.device_type.CPU),
                )
            )
    return out


def list_devices() -> list[tuple[str, str]]:
    """``(platform name, device name)`` of every OpenCL device, in ``PYOPENCL_CTX`` index order."""
    return [(d.platform, d.name) for d in devices()]


def device_info(device: cl.Device) -> DeviceInfo:
    """The :class:`DeviceInfo` of a pyopencl device (known for the devices of
    :func:`get_context`'s contexts, else found among :func:`devices`)."""
    info = _infos.get(device.int_ptr)
    if info is not None:
        return info
    for info in devices():
        if (info.platform, info.platform_version, info.name, info.driver_version) == (
            device.platform.name.strip(),
            device.platform.version.strip(),
            device.name.strip(),
            device.driver_version.strip(),
        ):
            return info
    raise OpenCLUnavailableError(f"device {device.name!r} is not among this process's OpenCL devices")


def preference_order(infos: list[DeviceInfo]) -> list[DeviceInfo]:
    """The order devices are tried in: PoCL first (newest version first), then the others as listed."""

    def pocl_version(info: DeviceInfo) -> tuple[int, ...]:
        m = re.search(r"PoCL (\d+)\.(\d+)", info.platform_version)
        return tuple(int(v) for v in m.groups()) if m else (0, 0)

    pocl = sorted((d for d in infos if d.is_pocl), key=pocl_version, reverse=True)
    return pocl + [d for d in infos if not d.is_pocl]


def get_context(device: str | None = None) -> cl.Context:
    """The shared context for a verified ``device``.

    ``device`` is ``None`` (``PYOPENCL_CTX`` if set, else the first device that passes the
    self-test, PoCL first), ``"pocl"``, an index ``"P:D"`` (platform, device) or a substring
    of a device or platform name. A device named here or by ``PYOPENCL_CTX`` that fails the
    self-test raises :class:`DeviceNotVerifiedError` saying why; no verified device at all
    raises :class:`OpenCLUnavailableError` listing each device's failure.
    """
    _require_pyopencl()
    key = device if device is not None else "env:" + os.environ.get("PYOPENCL_CTX", "")
    with _lock:
        ctx = _contexts.get(key)
    if ctx is not None:
        return ctx
    info = _pick_device(device)
    with _lock:
        ctx = _contexts.get(key)
        if ctx is None:
            ctx = _contexts.get(info.index)
        if ctx is None:
            ctx = cl.Context([_cl_device(info)])
            _contexts[info.index] = ctx
            _infos[ctx.devices[0].int_ptr] = info
        _contexts[key] = ctx
        return ctx


def _cl_device(info: DeviceInfo) -> cl.Device:
    p, d = (int(v) for v in info.index.split(":"))
    return cl.get_platforms()[p].get_devices()[d]


def _pick_device(device: str | None) -> DeviceInfo:
    from . import selftest, verify

    infos = devices()
    if not infos:
        raise OpenCLUnavailableError(f"no OpenCL device found; {_FIX}")
    spec, what = device, "device"
    if spec is None and os.environ.get("PYOPENCL_CTX"):
        spec, what = os.environ["PYOPENCL_CTX"], "PYOPENCL_CTX"
    if selftest.ALLOWED_VARIANTS is not None:  # the self-test's own child process
        if device is None:
            raise OpenCLUnavailableError("inside the self-test every context names its device")
        return _match(infos, device, "device")
    if spec is not None:
        info = _match(infos, spec, what)
        verdict = verify.verdict(info)
        if not verdict.ok:
            raise DeviceNotVerifiedError(f"{what}={spec!r}: {info.describe()} failed the self-test: {verdict.reason}")
        return info
    failures = []
    for info in preference_order(infos):
        verdict = verify.verdict(info)
        if verdict.ok:
            return info
        failures.append(f"{info.describe()}: {verdict.reason}")
    raise OpenCLUnavailableError(
        "no OpenCL device here passed the self-test (" + "; ".join(failures) + "). "
        f"Run ./install.sh (it adds the system PoCL, `apt-get install pocl-opencl-icd`), or {_NUMPY}"
    )


def variant_verified(device: cl.Device, variant: str) -> bool:
    """Whether kernel ``variant`` (a file of ``kernels/variants/``) passed the self-test on
    ``device``: its cached verdict says so (no verdict, no variant; nothing is run here)."""
    from . import selftest, verify

    if selftest.ALLOWED_VARIANTS is not None:  # inside the self-test itself
        return variant in selftest.ALLOWED_VARIANTS
    try:
        verdict = verify.cached_verdict(device_info(device))
    except OpenCLUnavailableError:
        return False
    return bool(verdict and verdict.ok and verdict.variants.get(variant, False))


def engine_speed(device: cl.Device, engine: str) -> float | None:
    """``engine``'s OpenCL frame rate over its numpy reference's on ``device``, as the self-test
    measured it (:data:`dynatex.player.opencl.selftest.SPEED_CASES`); None when not measured."""
    from . import selftest, verify

    if selftest.ALLOWED_VARIANTS is not None:  # inside the self-test itself
        return None
    try:
        verdict = verify.cached_verdict(device_info(device))
    except OpenCLUnavailableError:
        return None
    return verdict.speed.get(engine) if verdict and verdict.ok else None


def _match(infos: list[DeviceInfo], spec: str, what: str) -> DeviceInfo:
    spec = spec.strip()
    low = "portable computing language" if spec.lower() == "pocl" else spec.lower()
    parts = spec.split(":")
    if parts[0].isdigit() and all(p.isdigit() for p in parts[1:] if p) and len(parts) <= 2:
        index = f"{int(parts[0])}:{int(parts[1]) if len(parts) > 1 and parts[1] else 0}"
        for info in infos:
            if info.index == index:
                return info
        raise OpenCLUnavailableError(
            f"{what}={spec!r}: no such OpenCL platform/device index (available: {', '.join(d.index for d in infos)})"
        )
    matches = [d for d in infos if low in d.name.lower() or low in d.platform.lower()]
    if matches:
        return preference_order(matches)[0]
    names = "; ".join(f"{d.index} {d.platform}: {d.name}" for d in infos)
    raise OpenCLUnavailableError(f"{what}={spec!r} matches no OpenCL device (available: {names})")


def _require_pyopencl() -> None:
    if cl is None:
        raise OpenCLUnavailableError(f"pyopencl cannot be imported ({_IMPORT_ERROR}); {_FIX}")
