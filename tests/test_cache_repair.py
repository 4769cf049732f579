"""`skdgmpm.cache_repair` on a cache folder laid out as numba's (an index per function: its
version, then (stamp, {key: data file})): two variants of one kernel that define the same symbol
(the same uid from two processes) are removed with every library that embeds that symbol; the
others, and the index format, stay."""
import pickle

from skdgmpm import cache_repair


def _index(folder, name, entries):
    """An index ``name``.nbi and its data files: entries = [(cells, bytes)], keys as numba's
    (signature, target, (code hash, cells hash))."""
    overloads = {}
    for k, (cells, blob) in enumerate(entries, start=1):
        fname = f"{name}.{k}.nbc"
        (folder / fname).write_bytes(blob)
        overloads[(("int64",), "x86_64", ("code", cells))] = fname
    with open(folder / f"{name}.nbi", "wb") as f:
        pickle.dump("0.68", f, protocol=-1)
        f.write(pickle.dumps(("stamp", overloads), protocol=-1))
    return overloads


def _read(path):
    with open(path, "rb") as f:
        version = pickle.load(f)
        return version, pickle.loads(f.read())


def test_variants_sharing_a_symbol_are_removed_with_what_embeds_them(tmp_path):
    pkg = tmp_path / "skdgmpm"
    pkg.mkdir()
    # a library defines its function (uid 1 here) and the function's Python wrapper
    own = b"_ZN3mod12_3clocals_3e5innerB2v1B4abcdE5ArrayE _ZN7cpython3mod12_3clocals_3e5innerB2v1B4abcdE5ArrayE"
    other = b"_ZN3mod12_3clocals_3e5innerB2v7B4abcdE5ArrayE _ZN7cpython3mod12_3clocals_3e5innerB2v7B4abcdE5ArrayE"
    _index(pkg, "mod._f.locals.inner-10.py311", [("cells A", b"..." + own), ("cells B", own + b"..."),
                                                 ("cells C", other)])
    embedded = b"_ZN3mod12_3clocals_3e5innerB2v1B4abcdE5ArrayE"             # the kernel itself, linked into a loop
    _index(pkg, "parallel._loop.locals.loop-5.py311", [("key 1", b"code " + embedded), ("key 2", b"other code")])

    assert cache_repair.colliding_symbols(tmp_path) == {b"_ZN3mod12_3clocals_3e5innerB2v1B4abcdE"}
    would = cache_repair.repair(tmp_path, apply=False)
    assert sorted(p.name for p in would) == ["mod._f.locals.inner-10.py311.1.nbc", "mod._f.locals.inner-10.py311.2.nbc",
                                             "parallel._loop.locals.loop-5.py311.1.nbc"]
    assert all(p.exists() for p in would)                   # a check removes nothing
    assert cache_repair.main(["--check", str(tmp_path)]) == 1

    removed = cache_repair.repair(tmp_path)
    assert sorted(removed) == sorted(would) and not any(p.exists() for p in removed)
    version, (stamp, left) = _read(pkg / "mod._f.locals.inner-10.py311.nbi")
    assert (version, stamp) == ("0.68", "stamp") and list(left.values()) == ["mod._f.locals.inner-10.py311.3.nbc"]
    _, (_, left) = _read(pkg / "parallel._loop.locals.loop-5.py311.nbi")
    assert list(left.values()) == ["parallel._loop.locals.loop-5.py311.2.nbc"]
    assert cache_repair.colliding_symbols(tmp_path) == set()
    assert cache_repair.main(["--check", str(tmp_path)]) == 0


def test_an_unreadable_index_is_left_as_it_is(tmp_path, capsys):
    """An index that does not unpickle (a write cut short) is named and skipped, not a traceback:
    CI runs the repair before the tests."""
    (tmp_path / "mod.f-3.py311.nbi").write_bytes(b"not a pickle")
    assert cache_repair.repair(tmp_path) == []
    assert "mod.f-3.py311.nbi: not read" in capsys.readouterr().out
