"""The glibc heap setting of skdgmpm.heap: applied when a scene is built, never on import, and
left alone when the user asks."""
import subprocess
import sys

import pytest

SCRIPT = """
import ctypes.util, sys
import skdgmpm.heap as heap
import skdgmpm.run
assert heap.retain_freed_memory.cache_info().currsize == 0      # importing changes nothing
from skdgmpm.build import build
from skdgmpm.scene import load_scene
build(load_scene("bar_elastic_1d", ["grid.cells=4"]))
print(heap.retain_freed_memory())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc setting")
@pytest.mark.parametrize("keep, expected", [("0", "True"), ("1", "False")])
def test_heap_setting_applies_on_build_unless_kept(keep, expected):
    env = {"SKDGMPM_KEEP_MALLOC": keep, "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == expected


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc call")
def test_free_pages_are_released_after_the_set_up():
    from skdgmpm import heap

    assert heap.release_free_pages()


PAGES = """
import resource, sys
import numpy as np
import skdgmpm.heap as heap
heap.retain_freed_memory()
def touched(n):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.ones(n)
    del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
n = 2 ** 23                                  # 64 MiB: above glibc's largest mmap threshold
touched(n)
print(touched(n))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc setting")
def test_a_large_freed_block_is_reused_without_page_faults():
    """A 64 MiB array freed and allocated again (as a step's particle arrays at 1024^2 are) comes
    back from the heap warm: a fresh mapping faults its pages in again (16384 small pages, or
    with transparent huge pages about 500 faults, each zeroing 2 MiB: 4 ms against 2)."""
    env = {"PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", PAGES], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.split()[-1]) < 50
