"""Threads never change answers: the chunked passes (`skdgmpm.parallel`) give the same bits for
1, 2 and 3 threads (3: chunks of unequal length), for every scheme. The chunk length is lowered
so that these small grids are split into several chunks, as a 256^2 grid is."""
import threading
import time

import numba
import numpy as np
import pytest
import scipy.sparse as sp

from skdgmpm import parallel
from skdgmpm.build import build
from skdgmpm.scene import load_scene

STEPS = 4
CASES = {
    "dgmpm-ctu": ("plate_impact_neohookean_2d", ["grid.cells=[20, 15]", 'method.transverse="ctu"']),
    "dgmpm-dcu-rk2": ("plate_impact_neohookean_2d", ["grid.cells=[20, 15]", 'method.transverse="dcu"',
                                                     'method.integrator="rk2"', "method.cfl=0.4"]),
    "dgmpm-ctu-j2": ("plate_impact_j2_2d", ["grid.cells=[16, 12]"]),
    "ader-dgmpm-1": ("plate_impact_neohookean_2d", ['method.name="ader-dgmpm"', "method.cfl=0.4",
                                                    "grid.cells=[12, 9]", "particles.per_cell=[0.25, 0.75]"]),
    "rk-dgfem-1": ("plate_impact_neohookean_2d", ['method.name="rk-dgfem"', 'method.integrator="rk2"',
                                                  "method.cfl=0.4", "grid.cells=[12, 9]"]),
    "ader-dgmpm-2-flip": ("convergence_square", ['method.name="ader-dgmpm"', "method.order=2", "grid.cells=[5, 5]",
                                                 "particles.per_cell=[0.25, 0.5, 0.75]", 'method.backmap="flip"']),
    "ader-dgfem-2": ("plate_impact_neohookean_2d", ['method.name="ader-dgfem"', "method.order=2", "method.cfl=0.4",
                                                    "grid.cells=[8, 6]"]),
    "rk-dgfem-2-j2": ("plate_impact_j2_2d", ['method.name="rk-dgfem"', "method.order=2", 'method.integrator="rk4"',
                                             "method.cfl=0.4", "grid.cells=[8, 6]"]),
    "mpm-cd-cpgimp": ("mms_axis_aligned_2d", ["grid.cells=[12, 12]", 'method.name="mpm"', 'method.update="cd"']),
    "mpm-usl-hat": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'method.name="mpm"', 'method.update="usl"',
                                                   'method.shape="hat"', "method.cfl=0.4"]),
    "mpm-usf-cpgimp": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'method.name="mpm"', 'method.update="usf"',
                                                      "method.cfl=0.4"]),
    "mpm-uvf-ugimp": ("plate_impact_neohookean_2d", ["grid.cells=[12, 9]", 'method.name="mpm"', 'method.update="uvf"',
                                                     'method.shape="ugimp"', "method.cfl=0.4"]),
    "dgmpm-1d": ("bar_elastic_1d", ["grid.cells=200", "particles.per_cell=2", "method.cfl=0.5"]),
}


def _run(name, threads):
    parallel.set_threads(threads)
    scene, overrides = CASES[name]
    disc = build(load_scene(scene, overrides))
    state = disc.initial
    for _ in range(STEPS):
        state = disc.stepper.step(state)
    return state, disc.stepper.external_work, disc.stepper.energy(state)


@pytest.mark.parametrize("name", list(CASES))
def test_bits_do_not_depend_on_the_thread_count(name, monkeypatch):
    """The state, the boundary work and the energies (a run's rows: passes over the points)."""
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    try:
        runs = [_run(name, n) for n in (1, 2, 3)]
    finally:
        parallel.set_threads(None)
    one, work, energy = runs[0]
    assert one.step == STEPS and np.all(np.isfinite(one.U)) and np.all(np.isfinite(energy)) and energy[0] > 0
    for other, other_work, other_energy in runs[1:]:
        assert other.t == one.t and other_work == work and other_energy == energy
        for a, b in ((one.U, other.U), (one.Q, other.Q), (one.x, other.x)):
            assert np.array_equal(a, b)
        if one.dofs is not None:
            assert np.array_equal(one.dofs, other.dofs)
        if one.history is not None:
            assert np.array_equal(one.history, other.history)


@pytest.mark.parametrize("name", ["dgmpm-ctu", "dgmpm-dcu-rk2", "rk-dgfem-1", "ader-dgfem-2", "ader-dgmpm-1",
                                  "mpm-usl-hat", "mpm-usf-cpgimp"])
def test_every_pass_of_a_step_runs_in_compiled_chunk_loops(name, monkeypatch):
    """Every method's step runs its chunked passes in numba's compiled chunk loops (`parallel.
    chunked`, `parallel.compiled_chunks`), none on the pool, where numba's threading layer is
    OpenMP or TBB; the states have the pool's bits (the pool runs them all where the compiled
    loops are refused)."""
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    if not parallel._compiled_layer():
        pytest.skip(f"numba's threading layer here is {parallel.numba.threading_layer()}: the pool runs the passes")
    states = []
    rows = parallel.rows
    try:
        for compiled in (True, False):
            if not compiled:
                monkeypatch.setattr(parallel, "compiled_chunks", lambda n, min_rows=None: None)
            parallel.set_threads(2)
            scene, overrides = CASES[name]
            disc = build(load_scene(scene, overrides))
            state = disc.stepper.step(disc.initial)
            pooled = []
            monkeypatch.setattr(parallel, "rows", lambda n, call, min_rows=None: pooled.append(n) or rows(n, call,
                                                                                                         min_rows))
            for _ in range(STEPS - 1):
                state = disc.stepper.step(state)
            monkeypatch.setattr(parallel, "rows", rows)
            assert (pooled == []) == compiled, pooled
            states.append(state)
    finally:
        parallel.set_threads(None)
    for a, b in zip(*((s.U, s.Q, s.x) for s in states)):
        assert np.array_equal(a, b)


def test_compiled_chunks_follow_the_settings_and_set_numbas_thread_count(monkeypatch):
    """`parallel.compiled_chunks` (its bounds made once per size): the chunks of `parallel.chunks`
    for the thread count and MIN_ROWS of the moment, numba's thread count set to them; None on one
    thread or where the rows are too few for two threads (MIN_ROWS 600 here)."""
    if not parallel._compiled_layer() or numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba's compiled chunk loops do not run here")
    n = 1000
    try:
        for min_rows in (16, 600, 100):
            monkeypatch.setattr(parallel, "MIN_ROWS", min_rows)
            for t in (1, 2, 1, 2):
                parallel.set_threads(t)
                bounds = parallel.compiled_chunks(n)
                if t == 1 or min_rows == 600:
                    assert bounds is None
                    continue
                assert list(bounds) == [lo for lo, _ in parallel.chunks(n)] + [n]
                assert len(bounds) - 1 == 2 * parallel.PIECES and numba.get_num_threads() == 2
    finally:
        parallel.set_threads(None)


def test_chunks_cover_the_rows_once():
    for n in (0, 1, 5, 4097, 10_000):
        for parts in (1, 2, 3, 7):
            b = parallel.bounds(n, parts)
            assert b[0][0] == 0 and b[-1][1] == n
            assert all(hi == lo for (_, hi), (lo, _) in zip(b[:-1], b[1:]))


def test_rows_takes_every_chunk_once_and_a_slow_thread_takes_fewer(monkeypatch):
    """`parallel.rows`: every chunk once, results in chunk order, for any count; a thread the
    machine slows (here: the worker, each of its chunks made to last 20 ms) takes fewer chunks,
    the calling thread taking those left rather than waiting for it."""
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    main = threading.get_ident()
    try:
        for threads in (1, 2, 3):
            parallel.set_threads(threads)
            for n in (0, 5, 64, 201):
                taken = parallel.rows(n, lambda lo, hi: (lo, hi))
                team = min(threads, max(1, n // 16))
                assert taken == parallel.chunks(n) and len(taken) == (1 if team == 1 else parallel.PIECES * team)
        parallel.set_threads(2)

        def chunk(lo, hi):
            if threading.get_ident() != main:
                time.sleep(0.02)
            return threading.get_ident() == main
        by_main = parallel.rows(256, chunk)
        assert len(by_main) == 16 and sum(by_main) >= 12
    finally:
        parallel.set_threads(None)


@numba.njit(parallel=True)
def _taken_by(cost, thread):
    """A compiled chunk loop as the step's: chunk c, busy for cost[c] square roots, records the
    thread that took it."""
    n = len(cost)
    counter = np.zeros(1, np.int64)
    for _ in numba.prange(n):
        c = parallel.take_chunk(counter)
        while c < n:
            s = 0.0
            for i in range(cost[c]):
                s += np.sqrt(i + 1.0)
            thread[c] = numba.get_thread_id() + (0 if s > 0 else 100)
            c = parallel.take_chunk(counter)


def test_compiled_chunk_loops_take_chunks_as_each_thread_is_free():
    """numba deals a prange out in equal shares (8 and 8 of 16 here); with `parallel.take_chunk`
    each thread takes the next chunk left, so the thread held by a slow chunk (100 times the
    others, ~0.1 s) takes fewer of them, every chunk taken once."""
    if not parallel._compiled_layer() or numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("no compiled chunk loops on two threads here")
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        cost = np.full(16, 400_000)
        cost[0] = 40_000_000
        thread = np.full(16, -1)
        _taken_by(cost, thread)
    finally:
        numba.set_num_threads(previous)
    assert set(thread) <= {0, 1}
    slow = thread[0]
    assert np.count_nonzero(thread == slow) <= 4


def test_an_error_in_a_chunk_is_raised_and_the_threads_go_on(monkeypatch):
    """A chunk's error reaches the caller (once the chunks being run are done), and the next
    pass runs on the same threads."""
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)

    def chunk(lo, hi):
        if lo == parallel.chunks(256)[3][0]:
            raise ValueError("chunk 3")
        return lo
    try:
        parallel.set_threads(2)
        with pytest.raises(ValueError, match="chunk 3"):
            parallel.rows(256, chunk)
        assert parallel.rows(256, lambda lo, hi: lo) == [lo for lo, _ in parallel.chunks(256)]
    finally:
        parallel.set_threads(None)


def test_each_thread_runs_its_chunk_on_a_thread_of_its_own():
    """`parallel.each_thread`: one chunk per thread, all at once (a barrier every chunk waits at
    would time out otherwise), as the bench's probes need."""
    try:
        for threads in (1, 2, 3):
            parallel.set_threads(threads)
            barrier = threading.Barrier(threads, timeout=10)
            seen = parallel.each_thread(threads * parallel.MIN_ROWS, lambda lo, hi: (barrier.wait(),
                                                                                      threading.get_ident())[1])
            assert len(set(seen)) == threads
    finally:
        parallel.set_threads(None)


@numba.njit(nogil=True)
def _spec_probe(lo, hi, a, indptr, csr, cols, per_chunk, pair, scalar, out):
    """What each argument of a chunk holds (`parallel.chunked`'s letters), into out's rows; the
    chunk's first negative a, or -1."""
    first = -1
    for r in range(hi - lo):
        out[r, 0] = a[r] + scalar
        out[r, 1] = (indptr[r + 1] - indptr[r]) + 10 * (csr[0][r + 1] - csr[0][r]) + 100 * len(csr[1])
        out[r, 2] = cols[1, r]
        out[r, 3] = per_chunk
        out[r, 4] = pair[0][r] * pair[1][1]
        out[r, 5] = lo
        if a[r] < 0 and first < 0:
            first = r
    return first


@numba.njit(nogil=True)
def _chunk_sum(a):
    s = 0.0
    for x in a:
        s += x
    return s, len(a)


@pytest.mark.parametrize("compiled", [True, False])
def test_chunked_cuts_each_argument_as_its_spec_says(compiled, monkeypatch):
    """`parallel.chunked` on three threads, the loop compiled (numba's threads) or on the pool:
    each letter's cut of each chunk (rows, indptr rows, a CSR triple's rows, columns, the
    chunk's entry, a tuple's items, whole, lo and hi), the first failing row over the chunks,
    and each chunk's returned numbers in chunk order, as numpy computes them from the chunks.
    (The test's kernels are named with a hash of their source: the loops cached on disk are
    the package's, `parallel.kernel_name`.)"""
    if compiled and not parallel._compiled_layer():
        pytest.skip("no compiled chunk loops here")
    monkeypatch.setattr(parallel, "MIN_ROWS", 8)
    if not compiled:
        monkeypatch.setattr(parallel, "compiled_chunks", lambda n, min_rows=None: None)
    n = 100
    rng = np.random.default_rng(3)
    a, b = rng.random(n), rng.random(n)
    indptr = np.concatenate([[0], np.cumsum(rng.integers(0, 4, n))]).astype(np.int32)
    csr = (indptr, np.zeros(indptr[-1], np.int32), np.zeros(indptr[-1]))
    cols = rng.random((3, n))
    try:
        parallel.set_threads(3)
        parts = parallel.chunks(n)
        assert len(parts) > 3
        chunk_of = np.concatenate([np.full(hi - lo, k) for k, (lo, hi) in enumerate(parts)])
        lo_of = np.concatenate([np.full(hi - lo, lo) for lo, hi in parts])
        for bad, first in (([], -1), ([57, 23, 90], 23)):
            a[bad] = -1.0
            out = np.full((n, 6), np.nan)
            got = parallel.chunked(n, _spec_probe, "lhrickn(rw)wr",
                                   (a, indptr, csr, cols, np.arange(len(parts)) * 1.5, (b, a), 0.25, out), "first")
            assert got == first
            assert np.array_equal(out[:, 0], a + 0.25)
            assert np.array_equal(out[:, 1], np.diff(indptr) * 11 + 100 * len(csr[1]))
            assert np.array_equal(out[:, 2], cols[1])
            assert np.array_equal(out[:, 3], chunk_of * 1.5)
            assert np.array_equal(out[:, 4], b * a[1])
            assert np.array_equal(out[:, 5], lo_of)
        sums = parallel.chunked(n, _chunk_sum, "r", (b,), 2)
        assert np.array_equal(sums, [[sum(b[lo:hi].tolist()), hi - lo] for lo, hi in parts])
        with pytest.raises(ValueError, match="'x' unknown"):
            parallel.chunked(n, _chunk_sum, "x", (b,))
        with pytest.raises(ValueError, match="for 2 arguments"):
            parallel.chunked(n, _chunk_sum, "r", (b, b))
    finally:
        parallel.set_threads(None)


@numba.njit(nogil=True)
def _whole_count(lo, hi, x, out):
    for r in range(lo, hi):
        out[r] = len(x)


def test_chunked_plans_again_where_the_arguments_nest_otherwise(monkeypatch):
    """`parallel.chunked` keeps, per kernel and spec, its compiled loop and a function that
    flattens the arguments as they nested at the first call (`parallel._plan`): a ``w`` given an
    array, then a tuple of three arrays, then an array again, is each time read as given (the
    plan made anew where the nesting changed), and a call with too few arguments is still
    refused by name once a plan exists."""
    if not parallel._compiled_layer():
        pytest.skip("no compiled chunk loops here")
    monkeypatch.setattr(parallel, "MIN_ROWS", 8)
    n = 64
    out = np.zeros(n)
    try:
        parallel.set_threads(2)
        for x, count in ((np.zeros(5), 5), ((np.zeros(2), np.zeros(3), np.zeros(1)), 3), (np.zeros(7), 7),
                         (np.zeros(4), 4)):
            parallel.chunked(n, _whole_count, "lhww", (x, out))
            assert np.all(out == count)
        plan = parallel._PLANS[_whole_count, "lhww", 0]
        parallel.chunked(n, _whole_count, "lhww", (np.zeros(2), out))
        assert parallel._PLANS[_whole_count, "lhww", 0] is plan          # the same nesting: the same plan
        with pytest.raises(ValueError, match="for 1 arguments"):
            parallel.chunked(n, _whole_count, "lhww", (out,))
    finally:
        parallel.set_threads(None)


@numba.njit(nogil=True)
def _doubled_first_negative(x, out):
    first = -1
    for r in range(len(x)):
        out[r] = 2.0 * x[r]
        if first < 0 and x[r] < 0:
            first = r
    return first


@numba.njit(nogil=True)
def _chunk_length(lo, hi, out):
    for r in range(lo, hi):
        out[r] = hi - lo


def test_two_passes_together_return_and_write_what_each_does_alone(monkeypatch):
    """`parallel.together`: two passes in one compiled loop (the first's chunks, then the
    second's, from one counter) write the bits and return the results that `parallel.chunked`
    gives each alone, on 1, 2 and 3 threads: the first failing row of a "first" pass (a row of a
    later chunk than the first), numbers per chunk, and the second pass's chunks cut by its own
    ``min_rows`` (each row writes its chunk's length). Where the second pass has one chunk, it
    joins the first's loop all the same; with neither on the threads (one thread), they run
    through `chunked`. A plan per pair of kernels, made once."""
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    rng = np.random.default_rng(5)
    x = rng.random(1000) + 0.1
    x[[700, 400]] = -1.0
    b = rng.random(90)
    try:
        for threads in (1, 2, 3):
            parallel.set_threads(threads)
            for n_b, min_rows in ((90, 32), (90, 10 ** 6)):        # several chunks, one
                out_a, out_b, ref_a, ref_b = np.zeros(1000), np.zeros(n_b), np.zeros(1000), np.zeros(n_b)
                first = parallel.Pass(1000, _doubled_first_negative, "rr", (x, out_a), "first")
                second = parallel.Pass(n_b, _chunk_length, "lhw", (out_b,), 0, min_rows)
                assert parallel.together(first, second) == (400, None)
                assert parallel.chunked(1000, _doubled_first_negative, "rr", (x, ref_a), "first") == 400
                parallel.chunked(n_b, _chunk_length, "lhw", (ref_b,), 0, min_rows)
                assert np.array_equal(out_a, ref_a) and np.array_equal(out_b, ref_b)
                assert len(parallel.chunks(n_b, min_rows)) == (1 if threads == 1 or min_rows > 90 else 16)
                sums = parallel.together(parallel.Pass(90, _chunk_sum, "r", (b,), 2), first)
                assert np.array_equal(sums[0], parallel.chunked(90, _chunk_sum, "r", (b,), 2)) and sums[1] == 400
        if parallel._compiled_layer():
            assert (_doubled_first_negative, "rr", "first", _chunk_length, "lhw", 0) in parallel._PAIR_PLANS
    finally:
        parallel.set_threads(None)


def test_a_dcu_step_after_a_ctu_step_on_three_threads_keeps_the_heap_whole():
    """The compiled chunk loop once took its arguments as one tuple of arrays of several kinds:
    a CTU simulation on three threads, then a DCU one on two, aborted the process when the second
    was freed (free(): invalid next size). Now each array is a parameter of the loop: the same
    sequence, in a process of its own, ends cleanly."""
    import subprocess
    import sys
    code = """
import gc
from skdgmpm import bench, parallel
from skdgmpm.build import build
parallel.MIN_ROWS = 16
parallel.set_threads(3)
bench.measure_threads_here("dgmpm-ctu", 8, [1, 2], steps=3, warmup=1)
bench.alternate_threads(build(bench.scene_for("dgmpm-ctu", 8)), [1, 2], 4, warmup=1)
parallel.set_threads(1)
disc = build(bench.scene_for("dgmpm-dcu", 32))
step = bench.Stepping(disc)
bench._use_threads(2)
for _ in range(6):
    step()
del disc, step
gc.collect()
print("done")
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and done.stdout.strip() == "done", done.stderr[-2000:]


def test_a_bad_thread_count_is_refused():
    with pytest.raises(ValueError, match="threads = 0"):
        parallel.set_threads(0)


def test_run_threads_key_and_option(tmp_path):
    from skdgmpm.cli import main
    from skdgmpm.errors import InputError
    from skdgmpm.run import run

    r = run("bar_elastic_1d", ["run.threads=2", "grid.cells=20", "run.t_end=2e-5"], progress=False)
    assert r.summary()["threads"] == 2 and parallel._threads is None          # restored after the run
    with pytest.raises(InputError, match="run.threads"):
        run("bar_elastic_1d", ["run.threads=0"], progress=False)
    assert main(["run", "bar_elastic_1d", "--threads", "0", "--quiet", "--out", str(tmp_path / "x")]) == 2
    try:
        assert main(["run", "bar_elastic_1d", "--threads", "1", "--set", "grid.cells=20", "--set",
                     "run.t_end=2e-5", "--quiet", "--out", str(tmp_path / "y")]) == 0
        assert parallel.threads() == 1
    finally:
        parallel.set_threads(None)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_products_give_scipys_bits(threads, monkeypatch):
    """`parallel.matmul` is scipy's A @ X, on A.T.tocsr() scipy's A.T @ X, and `parallel.matmul_T`
    scipy's A.T @ X, bit for bit: unsorted rows with duplicate columns, vectors, strided columns, a
    scale, a width read at run time, and a sum continued from ``out``."""
    monkeypatch.setattr(parallel, "MIN_ROWS", 16)
    rng = np.random.default_rng(0)
    n, m, per_row = 500, 300, 9
    indptr, cols = np.arange(0, n * per_row + 1, per_row), rng.integers(0, m, n * per_row)
    data = rng.standard_normal((3, n * per_row))
    A = [sp.csr_matrix((data[k], cols, indptr), shape=(n, m)) for k in range(3)]
    try:
        parallel.set_threads(threads)
        pattern = parallel.Transposed(indptr, cols, m)
        for X in (rng.standard_normal(m), rng.standard_normal((m, 6)), rng.standard_normal((m, 2, 2))[:, :, 1],
                  rng.standard_normal((m, 90))):
            assert np.array_equal(parallel.matmul(A[0], X), A[0] @ X)
        for k in range(3):
            for Y in (rng.standard_normal(n), rng.standard_normal((n, 6)), rng.standard_normal((n, 2, 2))[:, :, 0],
                      rng.standard_normal((n, 90))):
                scale = rng.random(n)
                scaled = scale[:, None] * Y if Y.ndim == 2 else scale * Y
                assert np.array_equal(parallel.matmul(A[k].T.tocsr(), Y), A[k].T @ Y)
                assert np.array_equal(parallel.matmul(A[k].T.tocsr(), Y, scale=scale), A[k].T @ scaled)
                assert np.array_equal(parallel.matmul_T(pattern, data[k], Y), A[k].T @ Y)
                assert np.array_equal(parallel.matmul_T(pattern, data[k], Y, scale=scale), A[k].T @ scaled)
        out, Y = rng.standard_normal((m, 6)), rng.standard_normal((n, 6))
        expected = out.copy()
        for j in range(m):                  # the scatter into out it replaces, row by row
            for p in range(n):
                for q in range(indptr[p], indptr[p + 1]):
                    if cols[q] == j:
                        expected[j] += data[0, q] * Y[p]
        assert np.array_equal(parallel.matmul(A[0].T.tocsr(), Y, out.copy(), add=True), expected)
        assert np.array_equal(parallel.matmul_T(pattern, data[0], Y, out.copy(), add=True), expected)
    finally:
        parallel.set_threads(None)
