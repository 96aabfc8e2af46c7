#!/usr/bin/env bash
# Install dynatex (and, with an argument, its extras) into the current Python, then make
# sure an OpenCL platform that can compile kernels for this CPU is present.
#
#   ./install.sh          # the library and the `dynatex` command
#   ./install.sh test     # plus the test extra
#
# The pyopencl[pocl] wheels bring PoCL with no system setup. Their LLVM does not know
# every recent CPU (it fails with "unknown target CPU 'generic'", e.g. on AMD Zen 5); when
# that happens and apt-get is usable, the system PoCL (pocl-opencl-icd) is added, which
# picks its code generation from the CPU's features instead.
set -euo pipefail
cd "$(dirname "$0")"
extras="${1:-}"
python -m pip install --disable-pip-version-check -q -e ".${extras:+[$extras]}"

if python -m dynatex.player --check >/dev/null 2>&1; then
    exit 0
fi
echo "install.sh: no OpenCL device here can compile kernels; adding the system PoCL" >&2
if command -v apt-get >/dev/null 2>&1; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq >/dev/null 2>&1 || true
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd >/dev/null
fi
if ! python -m dynatex.player --check; then
    echo "install.sh: still no working OpenCL device; the player's numpy backend (backend='numpy') works without one" >&2
    exit 1
fi
