"""Shared test set-up.

The first run of a process that compiles a kernel prints one line on stderr saying so
(`skdgmpm.first_run.compile_notice`). Which test compiles first depends on the order and on
the state of the disk cache (a clean CI compiles everything), so the tests that check a command's
stderr line by line would see that line or not by chance: here it is written to a sink. The
notice itself is tested in tests/test_kernel_cache.py and tests/test_first_hour.py."""
import io

import pytest

from skdgmpm import compile_helper, first_run
from skdgmpm import run as run_module


@pytest.fixture(autouse=True)
def silent_compile_notice(monkeypatch):
    monkeypatch.setattr(run_module, "compile_notice",
                        lambda method, d, **kw: first_run.compile_notice(method, d, stream=io.StringIO(), **kw))


@pytest.fixture(autouse=True)
def no_compile_helper(monkeypatch):
    """A run compiles in its own process only (`skdgmpm.compile_helper` is tested where asked):
    which test compiles first depends on the order and the cache, and a second process each time
    would make the suite's time depend on them too."""
    monkeypatch.setenv(compile_helper.ENV, "0")
