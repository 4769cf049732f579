"""Per-process numbering of numba's compiled functions that no other process repeats.

numba names a compiled function by its qualified name, a number counted from 1 in each process
(``FunctionIdentity._unique_ids``, the ``v<uid>`` of the symbol) and its argument types. The
variants of a `kernel_cache` factory share the qualified name and often the types, so two of them
compiled first thing in two processes (a warm cache's subprocess compiles only its misses, the
first with uid 1) got one symbol, and loaded into one process the second ran the first's code
(docs/bench/session29.md §5; numba issue 10486 for the same clash after a fork). Each process,
and each child forked from one, counts from its own random start in [2^32, 2^52): the symbols
of two compilations then differ except with odds of about (compilations)^2 / 2^53. Cached
kernels keep their names: nothing is compiled again for this.
"""
import itertools
import os
import random

from numba.core import bytecode


def _reseed():
    bytecode.FunctionIdentity._unique_ids = itertools.count(random.SystemRandom().randrange(2 ** 32, 2 ** 52))


_reseed()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reseed)
