"""Numba compilation for the optimised kernels, cached on disk where a cache can be written."""

from __future__ import annotations

import hashlib
from pathlib import Path

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


def forget_stale_callers(package: Path, callee: str = "_fast.py") -> bool:
    """Drop the cached kernels of ``package`` that may have compiled in an older ``callee``.

    Numba checks a cached kernel only against its own file: a kernel in
    ``approach/looming.py`` or ``_parallel.py`` that calls into ``_fast.py`` would keep running
    the old machine code after ``_fast.py`` is edited. So the digest of ``callee`` is kept beside
    the cache, and when it differs (or is missing), the cache indexes (``*.nbi``) of every other
    file, in the package and its subpackages, are removed: numba then compiles those kernels
    afresh. A cache that cannot be written (a read-only installation, whose sources do not
    change either) is left alone.

    Returns whether indexes were removed.
    """
    cache = package / "__pycache__"
    stem = callee.removesuffix(".py")
    try:
        digest = hashlib.sha256((package / callee).read_bytes()).hexdigest()
        stamp = cache / f"{stem}.kernels.sha256"
        if stamp.is_file() and stamp.read_text(encoding="ascii") == digest:
            return False
        stale = [index for index in package.glob("**/__pycache__/*.nbi")
                 if not (index.parent == cache and index.name.startswith(stem + "."))]
        for index in stale:
            index.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest, encoding="ascii")
    except OSError:
        return False
    return bool(stale)


forget_stale_callers(Path(__file__).parent)
