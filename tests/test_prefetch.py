"""core/render/prefetch.py: a software prefetch compiles into kernels and changes nothing."""

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from relray.core.render.prefetch import prefetch_row


@njit(cache=True)
def _sum_prefetched(a, rows):
    s = 0.0
    for r in rows:
        prefetch_row(a, r)
        s += a[r, 0] + a[r, a.shape[1] - 1]
    return s


def test_a_prefetch_reads_nothing_wrong_and_writes_nothing():
    """Prefetching rows (float32 records, int64 and uint32 row numbers, the first and the
    last row) leaves the array as it was, and the loads after it see its values."""
    a = np.arange(64 * 16, dtype=np.float32).reshape(64, 16)
    before = a.copy()
    for rows in (np.array([0, 63, 5, 5, 17], np.int64), np.array([63, 0, 1], np.uint32)):
        want = float(sum(a[r, 0] + a[r, 15] for r in rows))
        assert _sum_prefetched(a, rows) == want
    assert np.array_equal(a, before)


def test_a_prefetch_takes_only_a_two_dimensional_array_and_an_integer_row():
    @njit
    def one_d(a):
        prefetch_row(a, 0)

    @njit
    def float_row(a):
        prefetch_row(a, 1.5)

    with pytest.raises(TypingError):
        one_d(np.zeros(4))
    with pytest.raises(TypingError):
        float_row(np.zeros((4, 4)))
