"""Compiled work of the bench's machine probes (`skdgmpm.bench`), apart from the bench itself so
that an edit of the bench keeps the kernel cache (`kernel_cache.source_digest`)."""
import math

from numba import njit


@njit(cache=True, nogil=True)
def arithmetic_rows(x, y, rounds):
    """y = the sum over r < ``rounds`` of sqrt(exp(x + r / 1000)), row by row: the arithmetic probe's
    work on a chunk, each row read and written once, its speed set by a core's arithmetic alone,
    whatever the chunk's size (the shift keeps the compiler from doing one round for all)."""
    for i in range(len(x)):
        s = 0.0
        for r in range(rounds):
            s += math.sqrt(math.exp(x[i] + r / 1000.0))
        y[i] = s
