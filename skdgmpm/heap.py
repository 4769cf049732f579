"""Keep freed memory in the process heap (glibc), so large temporaries reuse warm pages.

A time step allocates and frees dozens of arrays of a few MB (face states, tangents, residuals).
glibc serves blocks above its mmap threshold with fresh mappings and returns them to the kernel
on free, and trims the heap top likewise: every such temporary then pays a page fault per 4 KiB
and the kernel's zeroing of each page — about a third of a first-order DGMPM step at 128^2
(measured). Raising the mmap threshold to glibc's maximum (32 MiB on 64-bit) and the trim
threshold keeps freed blocks for the next step; a block above 32 MiB (a step's particle arrays
from about 1024^2 cells) is still mapped afresh unless mmap is off for the heap (M_MMAP_MAX = 0):
then every block comes from the heap and a freed one is reused warm (1024^2 DGMPM DCU on two
threads: 213 -> 106 ms per step, peak unchanged). Peak memory is unchanged (the freed blocks are
reused, not added); off glibc this is a no-op.

It is process-wide, so it is applied when a scene is built (a solver process), not on import;
SKDGMPM_KEEP_MALLOC=1 in the environment leaves glibc's defaults alone.

The set-up's temporaries are not the step's: once a scene is built, `release_free_pages` hands
the heap's free pages back (glibc's malloc_trim), which the raised trim threshold would keep
resident under the step's peak (512^2 DGMPM: about 80 B per cell of peak RSS).
"""
import ctypes
import ctypes.util
import functools
import os

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD, M_MMAP_MAX = -1, -3, -4          # <malloc.h>
MMAP_THRESHOLD = 32 * 2**20                          # glibc's upper bound on 64-bit
TRIM_THRESHOLD = 2**30


@functools.cache                                     # once per process (find_library runs ldconfig)
def retain_freed_memory():
    """Set glibc's mmap and trim thresholds (see the module docstring); True where applied."""
    if os.environ.get("SKDGMPM_KEEP_MALLOC") == "1":
        return False
    name = ctypes.util.find_library("c")
    try:
        mallopt = ctypes.CDLL(name).mallopt
    except (OSError, AttributeError, TypeError):     # no C library found, or not glibc
        return False
    return (bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
            and bool(mallopt(M_MMAP_MAX, 0)))


def release_free_pages():
    """Return the heap's free pages to the kernel (glibc ``malloc_trim(0)``); True where done."""
    name = ctypes.util.find_library("c")
    try:
        trim = ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError, TypeError):     # no C library found, or not glibc
        return False
    trim(0)
    return True
