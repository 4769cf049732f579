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
