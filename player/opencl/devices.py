"""OpenCL devices: the devices present, how they are named and the order they are tried in
(the lowest layer of the plumbing: which of them the player uses is :mod:`.context`'s choice).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass

from ..errors import OpenCLUnavailableError

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
    require_pyopencl()
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


def preference_order(infos: list[DeviceInfo]) -> list[DeviceInfo]:
    """The order devices are tried in: PoCL first (newest version first), then the others as listed."""

    def pocl_version(info: DeviceInfo) -> tuple[int, ...]:
        m = re.search(r"PoCL (\d+)\.(\d+)", info.platform_version)
        return tuple(int(v) for v in m.groups()) if m else (0, 0)

    pocl = sorted((d for d in infos if d.is_pocl), key=pocl_version, reverse=True)
    return pocl + [d for d in infos if not d.is_pocl]


def find_device(infos: list[DeviceInfo], spec: str, what: str) -> DeviceInfo:
    """The device of ``infos`` that ``spec`` names (``"pocl"``, an index ``"P:D"`` or a substring
    of a device or platform name); ``what`` names ``spec``'s origin in the error."""
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


def require_pyopencl() -> None:
    """Raise :class:`OpenCLUnavailableError` saying how to fix it when pyopencl cannot be imported."""
    if cl is None:
        raise OpenCLUnavailableError(f"pyopencl cannot be imported ({_IMPORT_ERROR}); {_FIX}")
