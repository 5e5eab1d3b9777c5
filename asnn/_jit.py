"""Numba compilation for the optimised kernels, cached on disk where a cache can be written."""

from __future__ import annotations

import hashlib
from pathlib import Path

from numba import config as numba_config
from numba import njit
from numba.core.caching import UserProvidedCacheLocator

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
    afresh, in the place numba keeps them: under ``NUMBA_CACHE_DIR`` where it is set (one
    folder per source folder), else beside the sources (``__pycache__``). A cache that cannot
    be written (a read-only installation, whose sources do not change either) is left alone.

    Returns whether indexes were removed.
    """
    stem = callee.removesuffix(".py")
    try:
        digest = hashlib.sha256((package / callee).read_bytes()).hexdigest()
        folders = [package, *(p for p in package.glob("**/") if p.name != "__pycache__")]
    except OSError:
        return False
    place = _cache_place()
    cache = place(package)
    try:
        stamp = cache / f"{stem}.kernels.sha256"
        if stamp.is_file() and stamp.read_text(encoding="ascii") == digest:
            return False
        stale = [index for folder in dict.fromkeys(folders) for index in place(folder).glob("*.nbi")
                 if not (folder == package and index.name.startswith(stem + "."))]
        for index in stale:
            index.unlink(missing_ok=True)
        cache.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest, encoding="ascii")
    except OSError:
        return False
    return bool(stale)


def _cache_place():
    """Where numba keeps the kernels of a source folder, as a function of the folder: under
    ``NUMBA_CACHE_DIR`` where it is set (numba's ``UserProvidedCacheLocator``, which names a
    folder there after the source folder's path), and nowhere else then (no stamp is written
    into an installed package's folder); else beside the sources."""
    if numba_config.CACHE_DIR:
        root = Path(numba_config.CACHE_DIR)
        return lambda folder: root / UserProvidedCacheLocator.get_suitable_cache_subpath(
            str(folder / "__init__.py"))
    return lambda folder: folder / "__pycache__"


forget_stale_callers(Path(__file__).parent)
