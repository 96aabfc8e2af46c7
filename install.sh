#!/usr/bin/env bash
# Install dynatex (and, with an argument, its extras) into the current Python, then make
# sure an OpenCL device that passes the player's self-test is present.
#
#   ./install.sh          # the library and the `dynatex` command
#   ./install.sh test     # plus the test extra
#
# The pyopencl[pocl] wheels bring PoCL with no system setup, but their LLVM does not know
# every CPU: on some it cannot compile at all, on others it builds kernels that crash or
# compute wrong. `python -m dynatex.player --check` runs the self-test (every kernel against
# its numpy reference, in a child process with a timeout) on every device; when no device
# passes and apt-get is usable, the system PoCL (pocl-opencl-icd) is added, which picks its
# code generation from the CPU's features. Without any verified device the player still
# works on its numpy backend, so this script never fails for want of OpenCL.
set -euo pipefail
cd "$(dirname "$0")"
extras="${1:-}"
python -m pip install --disable-pip-version-check -q -e ".${extras:+[$extras]}"

if report=$(python -m dynatex.player --check 2>&1); then
    exit 0
fi
echo "$report" >&2
echo "install.sh: no OpenCL device here passed the self-test; adding the system PoCL" >&2
if command -v apt-get >/dev/null 2>&1; then
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq >/dev/null 2>&1 || true
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq pocl-opencl-icd >/dev/null || true
fi
if ! python -m dynatex.player --check >&2; then
    echo "install.sh: still no verified OpenCL device; the player uses its numpy backend (slower)" >&2
fi
