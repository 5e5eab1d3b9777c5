"""Numba compilation for the optimised kernels, cached on disk where a cache can be written."""

from __future__ import annotations

from numba import njit

__all__ = ["kernel"]


def kernel(**options):
    """``numba.njit(cache=True, nogil=True, **options)``, or the same without the cache.

    Numba refuses ``cache=True`` at decoration time (at import) when it finds no writable place
    for the cache: a read-only installation run by a user without a writable home, as in a
    locked-down container. Such a process compiles the kernels at first use instead of loading
    them; it must not fail to import.
    """
    def decorate(func):
        try:
            return njit(cache=True, nogil=True, **options)(func)
        except RuntimeError:  # "cannot cache function ...: no locator available for file ..."
            return njit(cache=False, nogil=True, **options)(func)

    return decorate
