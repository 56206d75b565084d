"""Let numba's kernels use the full width of AVX-512 vectors where the processor has them.

LLVM tunes most AVX-512 processors to *prefer* 256-bit vectors (``prefer-256-bit``), a guard
against the clock reduction of the first AVX-512 server generation. The engine's hot loops (the
modal recursion, over ~50 modes) are throughput-bound and run ~1.3x faster with 512-bit vectors on
later processors. Before numba compiles anything, this module sets ``NUMBA_CPU_NAME`` and
``NUMBA_CPU_FEATURES`` to the host's name and features with that preference removed.

It does nothing when:

- the processor has no AVX-512F, or is of the Skylake-SP generation (``skylake-avx512``,
  ``cascadelake``, ``cooperlake``, Xeon Phi), where the preference is right;
- ``NUMBA_CPU_NAME`` or ``NUMBA_CPU_FEATURES`` is already set (your choice wins);
- ``WALLCAL_VECTOR_WIDTH=256`` is set (opt out).

The setting is process-wide (numba has no per-function vector width): other numba code in the
same process compiled after importing wallcal also gets 512-bit vectors. Numba's on-disk cache is
keyed by the processor name and features, so cached kernels stay consistent. Results change only
by round-off (the order of some floating-point sums).
"""

from __future__ import annotations

import os

_SKIP = {"skylake-avx512", "cascadelake", "cooperlake", "knl", "knm"}


def configure() -> str | None:
    """Apply the setting if it applies; return the feature string set, or None."""
    if os.environ.get("WALLCAL_VECTOR_WIDTH", "").strip() == "256":
        return None
    if "NUMBA_CPU_NAME" in os.environ or "NUMBA_CPU_FEATURES" in os.environ:
        return None
    try:
        from llvmlite import binding as ll

        name = ll.get_host_cpu_name()
        features = ll.get_host_cpu_features()
    except Exception:  # pragma: no cover - unusual llvmlite builds: keep numba's defaults
        return None
    if not features.get("avx512f", False) or name in _SKIP:
        return None
    flat = features.flatten() + ",-prefer-256-bit"
    os.environ["NUMBA_CPU_NAME"] = name
    os.environ["NUMBA_CPU_FEATURES"] = flat
    try:
        from numba.core import config

        config.reload_config()
    except Exception:  # pragma: no cover
        pass
    return flat
