"""The kernels' disk cache: callers of an edited ``_fast.py`` are compiled afresh."""

from asnn._jit import forget_stale_callers


def _package(tmp_path, source="x = 1\n"):
    (tmp_path / "_fast.py").write_text(source)
    cache = tmp_path / "__pycache__"
    cache.mkdir(exist_ok=True)
    for name in ("_fast._front-10.py311.nbi", "_parallel._serve-30.py311.nbi"):
        (cache / name).write_bytes(b"index")
    # a subpackage's kernels call into _fast.py too (asnn/approach/looming.py)
    sub = tmp_path / "approach" / "__pycache__"
    sub.mkdir(parents=True, exist_ok=True)
    for name in ("looming._solve-20.py311.nbi", "looming._solve-20.py311.1.nbc"):
        (sub / name).write_bytes(b"index")
    return cache


def _left(cache):
    return sorted(p.relative_to(cache.parent).as_posix()
                  for p in cache.parent.glob("**/__pycache__/*") if p.suffix in (".nbi", ".nbc"))


def test_callers_indexes_go_when_the_callee_changes_and_stay_while_it_does_not(tmp_path,
                                                                               monkeypatch):
    import asnn._jit as jit

    # numba's kernels beside the sources: NUMBA_CACHE_DIR unset, as it may be set where the
    # tests run (the systemd units' and the image's environment, a clone's)
    monkeypatch.setattr(jit.numba_config, "CACHE_DIR", "")
    cache = _package(tmp_path)
    kept = ["__pycache__/_fast._front-10.py311.nbi",
            "approach/__pycache__/looming._solve-20.py311.1.nbc"]
    # no digest yet (a cache from before): the callers' indexes go, the callee's own stay
    assert forget_stale_callers(tmp_path)
    assert _left(cache) == kept
    _package(tmp_path)  # numba writes them again
    assert not forget_stale_callers(tmp_path)
    assert len(_left(cache)) == 4
    (tmp_path / "_fast.py").write_text("x = 2\n")
    assert forget_stale_callers(tmp_path)
    assert _left(cache) == kept


def test_an_unreadable_package_is_left_alone(tmp_path):
    assert not forget_stale_callers(tmp_path / "missing")
    assert not (tmp_path / "missing").exists()


def test_callers_indexes_under_numba_cache_dir_go_too(tmp_path, monkeypatch):
    """An operations trial: with NUMBA_CACHE_DIR set (the systemd units, the image, a clone's
    environment) numba keeps no kernel beside the sources, and a caller of an edited _fast.py
    kept its old machine code: its results were silently the old code's."""
    import asnn._jit as jit
    from numba.core.caching import UserProvidedCacheLocator

    package, root = tmp_path / "pkg", tmp_path / "numba-cache"
    (package / "approach").mkdir(parents=True)
    (package / "_fast.py").write_text("x = 1\n")
    monkeypatch.setattr(jit.numba_config, "CACHE_DIR", str(root))

    def place(folder, name):  # where numba itself puts a kernel of a file in ``folder``
        return root / UserProvidedCacheLocator.get_suitable_cache_subpath(str(folder / name))

    files = [place(package, "_fast.py") / "_fast._front-10.py311.nbi",
             place(package, "_parallel.py") / "_parallel._serve-30.py311.nbi",
             place(package / "approach", "looming.py") / "looming._solve-20.py311.nbi"]
    for index in files:
        index.parent.mkdir(parents=True, exist_ok=True)
        index.write_bytes(b"index")
    assert forget_stale_callers(package)
    assert [f.exists() for f in files] == [True, False, False]  # the callee's own stay
    # nothing written beside the sources, where numba keeps nothing now (an installed
    # package's folder kept a stray stamp after pip uninstall: a packaging trial)
    assert not (package / "__pycache__").exists()
    for index in files:
        index.write_bytes(b"index")
    assert not forget_stale_callers(package)  # _fast.py unchanged: all kept
    (package / "_fast.py").write_text("x = 2\n")
    assert forget_stale_callers(package)
    assert [f.exists() for f in files] == [True, False, False]


def test_a_fresh_numba_cache_dir_gets_the_stamp_and_keeps_the_kernels_then(tmp_path, monkeypatch):
    """A mutation probe: under a NUMBA_CACHE_DIR still empty (a fresh image, a new clone's
    folder) the stamp's folder is made with its parents; otherwise no stamp was written, and
    every later start dropped the callers' kernels as stale (compiled again each time)."""
    import asnn._jit as jit
    from numba.core.caching import UserProvidedCacheLocator

    package, root = tmp_path / "pkg", tmp_path / "numba-cache"
    package.mkdir()
    (package / "_fast.py").write_text("x = 1\n")
    monkeypatch.setattr(jit.numba_config, "CACHE_DIR", str(root))
    assert not forget_stale_callers(package)  # nothing cached yet
    caller = root / UserProvidedCacheLocator.get_suitable_cache_subpath(
        str(package / "_parallel.py")) / "_parallel._serve-30.py311.nbi"
    caller.parent.mkdir(parents=True, exist_ok=True)
    caller.write_bytes(b"index")  # numba compiles and caches the caller
    assert not forget_stale_callers(package) and caller.exists()  # _fast.py unchanged: kept
