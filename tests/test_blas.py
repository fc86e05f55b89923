"""OpenBLAS thread control: it finds numpy's/scipy's OpenBLAS and restores what it changed."""

from oos_drake import blas


def _counts():
    return [pair[1]() for lib in blas._libraries() if (pair := blas._global_pair(lib))]


def test_finds_the_bundled_openblas_and_sets_it():
    before = _counts()
    assert before, "no OpenBLAS found in numpy/scipy"
    try:
        assert blas.limit_blas_threads(1) == len(before)
        assert all(c == 1 for c in _counts())
    finally:
        for lib, count in zip(blas._libraries(), before, strict=False):
            pair = blas._global_pair(lib)
            if pair:
                pair[0](count)


def test_context_manager_restores_the_previous_setting():
    blas.limit_blas_threads(2)
    before = _counts()

    @blas.with_single_threaded_blas
    def inside():
        return _counts()

    inside()
    assert _counts() == before


def test_a_serial_executor_restores_what_its_initializer_set():
    """``--workers 1`` runs the workers' initializer (one BLAS thread) in this process; after
    the executor the process has its own thread counts back (the in-process leak that made a
    later synthesis take another optimizer path)."""
    from oos_drake.processes import make_executor

    blas.limit_blas_threads(2)
    before = _counts()
    with make_executor(1, initializer=blas.limit_blas_threads, initargs=(1,)):
        assert all(count == 1 for count in _counts())
    assert _counts() == before
    with make_executor(2, "threads", initializer=blas.limit_blas_threads, initargs=(1,)):
        pass
    assert _counts() == before


def test_preserved_blas_threads_undoes_a_global_limit():
    blas.limit_blas_threads(2)
    before = _counts()
    with blas.preserved_blas_threads():
        blas.limit_blas_threads(1)
    assert _counts() == before
