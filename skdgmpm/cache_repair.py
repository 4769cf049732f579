"""Find and remove compiled kernels of the disk cache that would be linked to another kernel's code.

numba names a compiled function by its qualified name, a number unique in the process that
compiled it (``v<uid>``, counted from 1) and its argument types. A `kernel_cache.kernel_factory`
makes its variants (one per set of sizes) from one inner function, so they share the qualified
name, and often the argument types: two variants compiled by two processes (a test's subprocess,
a study's worker) can get the same uid, hence the same symbol. Each is cached under its own key,
but loaded into one process the second links to the first's code. Seen: a DCU step after a CTU
step ran CTU's cell records (25 numbers a record more) into DCU's empty split parts, and glibc
aborted (free(): invalid next size; docs/bench/session29.md §5).

Since `skdgmpm._uids` each process numbers from its own random start, and each variant compiles
under a qualified name of its own (`kernel_cache.variant_qualname`): new compilations no longer
clash, but caches made before may hold such pairs. `colliding_symbols` lists the symbols that two
variants of one index define; `repair` removes them and every cached library that embeds one (a
chunk loop carries the kernels it calls), so that they are compiled again. ``python -m
skdgmpm.cache_repair [--check] [ROOT]`` (ROOT: the cache of these sources, `kernel_cache.cache_dir`).
"""
import argparse
import collections
import os
import pickle
import re
import sys
from pathlib import Path


def _indexes(root):
    """{index path: (version, stamp, {key: data file name})} of a numba cache folder tree."""
    out = {}
    for idx in sorted(Path(root).rglob("*.nbi")):
        try:
            with open(idx, "rb") as f:
                version = pickle.load(f)
                stamp, overloads = pickle.loads(f.read())
        except Exception as exc:        # unreadable (another numba's format, a write cut short): numba recompiles it
            print(f"cache_repair: {idx}: not read ({type(exc).__name__}), left as it is")
            continue
        out[idx] = (version, stamp, overloads)
    return out


def _own_symbols(index, blob):
    """The symbols (without the Python wrapper's prefix) that a library of ``index`` defines for
    its own function: the name after the last dot of the index's file name."""
    name = index.name.split("-")[0].split(".")[-1].encode()
    pattern = rb"_ZN7cpython([0-9A-Za-z_$]*?" + str(len(name)).encode() + name + rb"B[0-9]+v[0-9]+B[0-9A-Za-z_]+?E)"
    return {b"_ZN" + s for s in re.findall(pattern, blob)}


def colliding_symbols(root, indexes=None):
    """Symbols defined by two entries of one index that are different variants (closure cells)."""
    found = set()
    for idx, (_, _, overloads) in (indexes or _indexes(root)).items():
        owners = collections.defaultdict(set)
        for key, fname in overloads.items():
            path = idx.parent / fname
            if path.exists():
                for s in _own_symbols(idx, path.read_bytes()):
                    owners[s].add(repr(key[2]))
        found |= {s for s, cells in owners.items() if len(cells) > 1}
    return found


def repair(root, apply=True):
    """Remove from the cache at ``root`` every entry whose library holds a colliding symbol (its
    data file, its line in the index); returns the paths removed (or, without ``apply``, that
    would be)."""
    indexes = _indexes(root)
    bad = colliding_symbols(root, indexes)
    removed = []
    for idx, (version, stamp, overloads) in indexes.items() if bad else ():
        keep = {}
        for key, fname in overloads.items():
            path = idx.parent / fname
            if path.exists() and any(s in path.read_bytes() for s in bad):
                removed.append(path)
                if apply:
                    os.remove(path)
            else:
                keep[key] = fname
        if apply and len(keep) != len(overloads):
            with open(idx, "wb") as f:       # numba's index format: its version, then (stamp, overloads)
                pickle.dump(version, f, protocol=-1)
                f.write(pickle.dumps((stamp, keep), protocol=-1))
    return removed


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("root", nargs="?", help="cache folder (default: this package's, kernel_cache.cache_dir)")
    parser.add_argument("--check", action="store_true", help="only list what would be removed; exit 1 if anything")
    args = parser.parse_args(argv)
    if args.root is None:
        from .kernel_cache import cache_dir
        args.root = cache_dir()
    if not Path(args.root).is_dir():
        print(f"cache_repair: no cache at {args.root}: nothing to check")
        return 0
    removed = repair(args.root, apply=not args.check)
    verb = "to remove" if args.check else "removed"
    print(f"cache_repair: {args.root}: {len(removed)} compiled kernel(s) {verb} (a symbol shared by two variants)")
    for path in removed:
        print(f"  {path}")
    return 1 if args.check and removed else 0


if __name__ == "__main__":
    sys.exit(main())
