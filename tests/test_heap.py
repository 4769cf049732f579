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
