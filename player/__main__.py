"""``python -m dynatex.player [--check]``: list OpenCL devices and the one the player would use."""

from .opencl.verify import _main

raise SystemExit(_main())
