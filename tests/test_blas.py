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
