"""The one place where JIT flags are set.

Every kernel is compiled with :func:`kernel`. Compiled code is cached on disk next to the
sources, so only the first run on a machine pays the compile time. Setting the environment
variable ``NUMBA_DISABLE_JIT=1`` runs the same kernels as plain Python (the tests do this
to check kernels line by line).
"""

from __future__ import annotations

import numba

kernel = numba.njit(cache=True, nogil=True, boundscheck=False)
"""Decorator for the compute kernels: nopython, cached, GIL released."""

inline_kernel = numba.njit(cache=True, nogil=True, boundscheck=False, inline="always")
"""Decorator for a small kernel that other kernels share, compiled into each of them rather than
called (a call in a hot loop costs as much as the work it does)."""

generated_kernel = numba.njit(nogil=True, boundscheck=False)
"""Decorator for kernels made at run time that close over other kernels (the compiled rollout's
loop, one per behaviour): compiled once per process, since numba caches no closure on disk."""

parallel_kernel = numba.njit(cache=True, nogil=True, boundscheck=False, parallel=True)
"""Decorator for kernels that loop over worlds with ``prange`` (threads: ``NUMBA_NUM_THREADS``)."""

prange = numba.prange
