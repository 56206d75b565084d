"""How wallcal's numba kernels are compiled: one set of flags, so that numba compiles what they share once.

numba compiles the numpy functions a kernel calls (``np.empty``) once per set of compile flags of the
calling function, not once per process: on a fresh install (empty kernel cache) each further set of
flags among the kernels that allocate costs another compilation of the same code. The engine's kernels
therefore share one set:

- they release the GIL (the engine runs parts of a batch in threads, :func:`wallcal.engines.fd.in_threads`);
- division follows IEEE arithmetic (``error_model="numpy"``: inf or nan, no exception raised inside a worker
  thread; the walls reach the kernels checked, :func:`wallcal.grid.assemble_lines`, and the modal path
  raises :class:`~wallcal.errors.EngineError` when a candidate's final state is not finite);
- compiled results are cached on disk (``cache=True``, ``NUMBA_CACHE_DIR`` to relocate), and no C entry
  point is compiled (nothing calls them through one).

:func:`kernel` is the decorator of the functions Python calls, :func:`inner` that of the functions only
compiled code calls (without the CPython entry point either). ``fastmath`` (the modal recursion and input
terms, the lambda(T) step) makes another set of flags: a numpy function called under it compiles again.
"""

from __future__ import annotations

from numba import njit

FLAGS = {"cache": True, "nogil": True, "error_model": "numpy", "no_cfunc_wrapper": True}


def kernel(fn):
    """Compile ``fn`` (called from Python) with wallcal's kernel flags."""
    return njit(**FLAGS)(fn)


def inner(fastmath: bool | set[str] = False):
    """The decorator of a function that only compiled code calls: wallcal's flags, no CPython entry point."""
    return njit(**FLAGS, fastmath=fastmath, no_cpython_wrapper=True)
