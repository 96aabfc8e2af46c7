"""The context the player draws with: one per device, on a device that passed the self-test
(its verdict, :mod:`.verify`), and what that verdict allows there (kernel variants, engines
measured slower than numpy).
"""

from __future__ import annotations

import os
import threading

from ..errors import DeviceNotVerifiedError, OpenCLUnavailableError
from . import verify
from .devices import _FIX, _NUMPY, DeviceInfo, cl, devices, find_device, preference_order, require_pyopencl

_lock = threading.Lock()
_contexts: dict[str, cl.Context] = {}
_infos: dict[int, DeviceInfo] = {}  # device handle -> its DeviceInfo, for get_context's devices


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


def get_context(device: str | None = None) -> cl.Context:
    """The shared context for a verified ``device``.

    ``device`` is ``None`` (``PYOPENCL_CTX`` if set, else the first device that passes the
    self-test, PoCL first), ``"pocl"``, an index ``"P:D"`` (platform, device) or a substring
    of a device or platform name. A device named here or by ``PYOPENCL_CTX`` that fails the
    self-test raises :class:`DeviceNotVerifiedError` saying why; no verified device at all
    raises :class:`OpenCLUnavailableError` listing each device's failure.
    """
    require_pyopencl()
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
    infos = devices()
    if not infos:
        raise OpenCLUnavailableError(f"no OpenCL device found; {_FIX}")
    spec, what = device, "device"
    if spec is None and os.environ.get("PYOPENCL_CTX"):
        spec, what = os.environ["PYOPENCL_CTX"], "PYOPENCL_CTX"
    if spec is not None:
        info = find_device(infos, spec, what)
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
    ``device``: its cached verdict says so (no verdict, no variant; nothing is run here; in the
    self-test's child, the variants the check under way allows: :func:`.verify.suppose`)."""
    try:
        verdict = verify.cached_verdict(device_info(device))
    except OpenCLUnavailableError:
        return False
    return bool(verdict and verdict.ok and verdict.variants.get(variant, False))


def engine_speed(device: cl.Device, engine: str) -> dict | None:
    """``engine``'s speed figure on ``device`` (:func:`.verify.speed_figure`: OpenCL's rate over
    numpy's, and ``"opencl"``, whether ``backend="auto"`` takes OpenCL), measured again first
    where it is unsettled, old or from another configuration (:func:`.verify.speed_stale`);
    None when not measured."""
    try:
        info = device_info(device)
    except OpenCLUnavailableError:
        return None
    return verify.speed(info, engine)
