"""LAPACK routines for the numba kernels: scipy's (``scipy.linalg.cython_lapack``), called by name.

A kernel calls a routine declared here as an external function ``wallcal_<routine>``; :func:`link` binds
these names to scipy's functions in numba's JIT linker (once per process, before a kernel that calls them
is compiled or loaded from the cache). The compiled code holds only the names, no address of this process,
so numba caches it, and compiling a call costs next to nothing (the routine is compiled already). The
routines are plain C functions: they do not touch the GIL, and those used here call no multi-threaded BLAS.

Arguments follow LAPACK's Fortran convention: every argument is a pointer (``arr.ctypes`` of a numpy array
in the kernel), integers are int32, characters uint8, matrices column-major (a C-ordered ``(n, ld)`` array
is the Fortran ``(ld, n)`` one).
"""

from __future__ import annotations

from numba import types
from numba.core.typing import signature

_P = types.voidptr

#: ``dpbstf(uplo, n, kd, ab, ldab, info)``: split Cholesky factorisation ``B = S^T S`` of a symmetric
#: positive definite band matrix (for :data:`dsbgst`)
dpbstf = types.ExternalFunction("wallcal_dpbstf", signature(types.void, *([_P] * 6)))
#: ``dsbgst(vect, uplo, n, ka, kb, ab, ldab, bb, ldbb, x, ldx, work, info)``: reduces the banded pencil
#: ``A x = lambda B x`` (``B`` split-factorised by :data:`dpbstf`) to the standard ``C y = lambda y`` with ``C``
#: of ``A``'s bandwidth, ``C = X^T A X``, ``X^T B X = I``, ``x = X y``
dsbgst = types.ExternalFunction("wallcal_dsbgst", signature(types.void, *([_P] * 13)))

ROUTINES = ("dpbstf", "dsbgst")
_linked = False


def link() -> None:
    """Bind the names ``wallcal_<routine>`` of :data:`ROUTINES` to scipy's LAPACK in numba's JIT linker
    (idempotent; adds only these names, nothing else in the process changes)."""
    global _linked
    if _linked:
        return
    import llvmlite.binding as ll
    from numba.extending import get_cython_function_address

    for name in ROUTINES:
        ll.add_symbol("wallcal_" + name, get_cython_function_address("scipy.linalg.cython_lapack", name))
    _linked = True
