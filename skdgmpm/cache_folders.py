"""The compiled kernels' folders on disk: one per source digest (`kernel_cache.cache_dir`), listed
and pruned (``skdgmpm cache [--prune]``), and written one process at a time (`lock_writes`).

Every edit of a file with compiled code, and every release, files its kernels under a new digest
(60-70 MB for every method and dimension); the folders of other digests stay until removed: a
second checkout or venv with other sources uses its own. Only folders named ``kernels-<16 hex
digits>`` (with a `kernel_cache.build_tag` suffix or none) directly under the cache's base are
touched, never anything else there (the base may be a $NUMBA_CACHE_DIR that other code shares).

Two processes compiling into one folder (two runs side by side on a cold cache, a run and its
compile helper's merge) would otherwise race in numba's writes of a function's index: numba
(`numba.core.caching.IndexDataCacheFile.save`) reads the index, picks the first data file number
it does not list, writes the index, then the data, and takes no lock. Two processes saving two
signatures of one function can both pick number n; where one writes its index last and the other
its data last, the index pairs that key with the other signature's code, which a later run would
load and call with the wrong types. `lock_writes` makes each save of this package's kernels hold
the folder's lock (`locked`) from its read of the index to its data's rename. Loads take no lock:
each file is renamed into place whole, and a key whose data is not there yet reads as a miss.
(No compiled code here: this module is not part of the kernels' cache key.)
"""
import contextlib
import os
import re
import shutil
import stat
import time
from pathlib import Path

from . import kernel_cache

_FOLDER = re.compile(r"kernels-[0-9a-f]{16}(-[a-z0-9]+)*")     # -debug, ...: `kernel_cache.build_tag`
LOCK = ".writes.lock"           # in a kernel folder: held by each save into it (`locked`)


@contextlib.contextmanager
def locked(folder):
    """An exclusive lock of the kernel folder ``folder`` (its file `LOCK`) for the block, where
    the system and the file system have one (elsewhere none: numba's own writes, as before)."""
    try:
        import fcntl
        os.makedirs(folder, exist_ok=True)
        f = open(os.path.join(folder, LOCK), "a")
    except (ImportError, OSError):
        yield
        return
    with f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX)
        except OSError:                 # e.g. a network file system without locks
            yield
            return
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def lock_writes():
    """Make numba save each kernel of this package (a file of <base>/kernels-<digest>/<package>/)
    under its kernel folder's lock (see the module's docstring); every other cache's saves as
    before. Idempotent."""
    from numba.core.caching import IndexDataCacheFile

    save = IndexDataCacheFile.save
    if getattr(save, "locks_kernel_folders", False):
        return

    def locked_save(self, key, data):
        folder = os.path.dirname(self._cache_path)
        if not _FOLDER.fullmatch(os.path.basename(folder)):
            return save(self, key, data)
        with locked(folder):
            return save(self, key, data)

    locked_save.locks_kernel_folders = True
    IndexDataCacheFile.save = locked_save


def folders(base=None):
    """[(path, bytes, last written (epoch s), current?)] of the kernel folders under ``base`` (the
    cache's, `kernel_cache.cache_base`, by default), the most recently written first."""
    base = Path(base or kernel_cache.cache_base())
    current = os.path.basename(kernel_cache.cache_dir())
    rows = []
    if base.is_dir():
        for path in base.iterdir():
            if path.is_dir() and not path.is_symlink() and _FOLDER.fullmatch(path.name):
                stats = [st for st in map(_stat, path.rglob("*")) if st is not None and stat.S_ISREG(st.st_mode)]
                size = sum(st.st_size for st in stats)
                written = max((st.st_mtime for st in stats), default=path.stat().st_mtime)
                rows.append((path, size, written, path.name == current))
    return sorted(rows, key=lambda row: (not row[3], -row[2]))


def _stat(path):
    """os.stat of a file, None where it is gone (a process compiling beside this one replaces files)."""
    try:
        return path.stat()
    except OSError:
        return None


def prune(base=None):
    """Remove every kernel folder under ``base`` but the current sources' (`folders`); returns the
    removed [(path, bytes)] and those that could not be, [(path, reason)] (e.g. another user's)."""
    removed, failed = [], []
    for path, size, _, current in folders(base):
        if not current:
            try:
                shutil.rmtree(path)
            except OSError as exc:
                failed.append((path, exc.strerror or str(exc)))
            else:
                removed.append((path, size))
    return removed, failed


def report(rows, now=None):
    """Lines describing `folders`' rows, and their total."""
    now = time.time() if now is None else now
    lines = []
    for path, size, written, current in rows:
        days = (now - written) / 86400
        age = "today" if days < 1 else "1 day ago" if days < 2 else f"{days:.0f} days ago"
        lines.append(f"{path}  {size / 2 ** 20:7.1f} MiB  written {age}" + ("  (these sources)" if current else ""))
    total = sum(row[1] for row in rows)
    lines.append(f"{len(rows)} folder(s), {total / 2 ** 20:.1f} MiB")
    return lines
