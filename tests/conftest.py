"""Shared test set-up.

The first run of a process that compiles a kernel prints one line on stderr saying so
(`skdgmpm.first_run.compile_notice`). Which test compiles first depends on the order and on
the state of the disk cache (a clean CI compiles everything), so the tests that check a command's
stderr line by line would see that line or not by chance: here it is written to a sink. The
notice itself is tested in tests/test_kernel_cache.py and tests/test_first_hour.py."""
import io

import pytest

from skdgmpm import first_run
from skdgmpm import run as run_module


@pytest.fixture(autouse=True)
def silent_compile_notice(monkeypatch):
    monkeypatch.setattr(run_module, "compile_notice",
                        lambda method, d: first_run.compile_notice(method, d, stream=io.StringIO()))
