"""The compiled kernels' folders on disk (`skdgmpm.cache_folders`, ``skdgmpm cache [--prune]``): one
per source digest; listed with their sizes, the current sources' first; pruned to the current one,
nothing else under the cache's base touched (it may be a $NUMBA_CACHE_DIR shared with other code)."""
import os

from skdgmpm import cache_folders, cli, kernel_cache


def cache_tree(base):
    """A base with the current sources' folder, two older ones and things that are not ours. Returns
    the folders' paths and their bytes."""
    current = base / os.path.basename(kernel_cache.cache_dir())
    old_a, old_b = base / "kernels-0123456789abcdef", base / "kernels-fedcba9876543210"
    sizes = {}
    for folder, n in ((current, 300), (old_a, 1000), (old_b, 20)):
        (folder / "skdgmpm").mkdir(parents=True)
        (folder / "skdgmpm" / "k.nbc").write_bytes(b"x" * n)
        (folder / "skdgmpm" / "k.nbi").write_bytes(b"y" * 7)
        sizes[folder] = n + 7
    (base / "kernels-notadigest").mkdir()                       # not a digest's name
    (base / "other_package").mkdir()
    (base / "kernels-0000000000000000").write_text("a file")    # a file, not a folder
    return current, old_a, old_b, sizes


def test_folders_lists_the_digests_folders_only_the_current_first(tmp_path):
    current, old_a, old_b, sizes = cache_tree(tmp_path)
    for f in (old_b / "skdgmpm").iterdir():                     # written long ago: listed last
        os.utime(f, (1e9, 1e9))
    rows = cache_folders.folders(tmp_path)
    assert [row[0] for row in rows] == [current, old_a, old_b]
    assert [row[1] for row in rows] == [sizes[current], sizes[old_a], sizes[old_b]]
    assert [row[3] for row in rows] == [True, False, False]
    lines = cache_folders.report(rows)
    assert "(these sources)" in lines[0] and lines[-1] == f"3 folder(s), {sum(sizes.values()) / 2 ** 20:.1f} MiB"


def test_prune_keeps_the_current_sources_folder_and_everything_not_ours(tmp_path):
    current, old_a, old_b, sizes = cache_tree(tmp_path)
    removed, failed = cache_folders.prune(tmp_path)
    assert sorted(removed) == sorted([(old_a, sizes[old_a]), (old_b, sizes[old_b])]) and failed == []
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [current.name, "kernels-notadigest", "other_package", "kernels-0000000000000000"])
    assert (current / "skdgmpm" / "k.nbc").read_bytes() == b"x" * 300
    assert cache_folders.prune(tmp_path) == ([], [])


def test_the_command_lists_then_prunes(tmp_path, monkeypatch, capsys):
    current, old_a, old_b, _ = cache_tree(tmp_path)
    monkeypatch.setattr(kernel_cache, "cache_base", lambda: str(tmp_path))
    assert cli.main(["cache"]) == 0
    out = capsys.readouterr().out
    assert str(old_a) in out and str(old_b) in out and "3 folder(s)" in out
    assert old_a.exists()                                       # listing removes nothing
    assert cli.main(["cache", "--prune"]) == 0
    out = capsys.readouterr().out
    assert f"removed {old_a}" in out and "2 folder(s) removed" in out
    assert not old_a.exists() and not old_b.exists() and current.exists()


def waits_for_lock(folder, work, written):
    """Run ``work`` in a thread while another holds ``folder``'s lock (`cache_folders.locked`, as
    another process would): assert it waits, not having written the path ``written``, and goes on
    once the lock is released."""
    import threading

    held, release = threading.Event(), threading.Event()

    def hold():
        with cache_folders.locked(str(folder)):
            held.set()
            release.wait(10)

    holder = threading.Thread(target=hold)
    holder.start()
    held.wait(10)
    mine = threading.Thread(target=work)
    mine.start()
    mine.join(0.3)
    assert mine.is_alive() and not written.exists()        # waiting for the lock
    release.set()
    holder.join()
    mine.join(10)
    assert not mine.is_alive()


def test_a_save_into_a_kernel_folder_waits_for_its_lock(tmp_path):
    """numba's save of one of the package's kernels (`lock_writes`, installed on import) holds its
    kernel folder's lock from its read of the index to its data's rename; a save into any other
    cache does not take it."""
    from numba.core.caching import IndexDataCacheFile

    ours, other = tmp_path / os.path.basename(kernel_cache.cache_dir()), tmp_path / "numba_cache"   # as `Locator` files them
    for folder in (ours / "skdgmpm", other / "pkg"):
        folder.mkdir(parents=True)

    IndexDataCacheFile(str(other / "pkg"), "m.f-10.py311", "stamp").save(("sig",), "code")
    assert not any(path.name == cache_folders.LOCK for path in other.rglob("*"))        # not ours: no lock

    def save():
        IndexDataCacheFile(str(ours / "skdgmpm"), "m.f-10.py311", "stamp").save(("sig",), "code")

    waits_for_lock(ours, save, ours / "skdgmpm" / "m.f-10.py311.nbi")
    assert IndexDataCacheFile(str(ours / "skdgmpm"), "m.f-10.py311", "stamp").load(("sig",)) == "code"


SAVER = """
import os, sys, time
import skdgmpm  # noqa: F401  (numba's saves into kernel folders locked)
from numba.core.caching import IndexDataCacheFile
folder, who, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
open(os.path.join(folder, "..", "ready-" + who), "w").close()
while len([f for f in os.listdir(os.path.join(folder, "..")) if f.startswith("ready-")]) < 2:
    time.sleep(0.001)
cache = IndexDataCacheFile(folder, "m.f-10.py311", "stamp")
for i in range(n):
    cache.save((who + str(i),), who + str(i))
"""


def test_two_processes_saving_into_one_kernel_folder_keep_every_key_with_its_own_code(tmp_path):
    """Two processes saving different signatures of one function into one kernel folder at the
    same time, as two runs compiling side by side on a cold cache do. Without the lock numba's
    saves race (both pick one data file number; the index of one and the data of the other win):
    this test's processes without the lock kept 329-356 of the 600 keys, and 61-92 of those read
    another key's data (three rounds, numba 0.68). With it, every key is kept with its own data."""
    import subprocess
    import sys

    from numba.core.caching import IndexDataCacheFile

    folder, n = tmp_path / "kernels-0123456789abcdef" / "skdgmpm", 300
    folder.mkdir(parents=True)
    savers = [subprocess.Popen([sys.executable, "-c", SAVER, str(folder), who, str(n)]) for who in "AB"]
    assert [p.wait(120) for p in savers] == [0, 0]
    cache = IndexDataCacheFile(str(folder), "m.f-10.py311", "stamp")
    index = cache._load_index()
    assert sorted(index) == sorted((who + str(i),) for who in "AB" for i in range(n))
    assert all(cache.load(key) == key[0] for key in index)


def test_where_the_file_system_has_no_locks_a_save_goes_on_unlocked(tmp_path, monkeypatch):
    """flock refused (a network file system, ENOLCK) or the lock file not writable: numba's save as
    before, never an error inside a compilation."""
    import errno
    import fcntl

    from numba.core.caching import IndexDataCacheFile

    def refused(*args):
        raise OSError(errno.ENOLCK, "No locks available")

    folder = tmp_path / "kernels-0123456789abcdef"
    (folder / "skdgmpm").mkdir(parents=True)
    with monkeypatch.context() as m:
        m.setattr(fcntl, "flock", refused)
        IndexDataCacheFile(str(folder / "skdgmpm"), "m.f-10.py311", "stamp").save(("a",), "code a")
    (folder / cache_folders.LOCK).unlink()
    (folder / cache_folders.LOCK).mkdir()          # cannot be opened as a file
    IndexDataCacheFile(str(folder / "skdgmpm"), "m.f-10.py311", "stamp").save(("b",), "code b")
    cache = IndexDataCacheFile(str(folder / "skdgmpm"), "m.f-10.py311", "stamp")
    assert (cache.load(("a",)), cache.load(("b",))) == ("code a", "code b")
