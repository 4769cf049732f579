"""The output folder of a run: locked while a run writes it, and consistent at every moment.

A run writes straight into its ``--out`` folder, so what is there when it dies (Ctrl-C, the
scheduler's SIGTERM, SIGKILL, a full disk) is what it had done:

- every file is written under a hidden temporary name in the same folder and renamed over its
  final name (`atomic_write`): a reader, or a run killed midway, sees the old file or the new one,
  never part of one. A frame is renamed into place before the ``.pvd`` that lists it, and
  ``energy.csv``, ``probes.csv`` (with probes), ``summary.json`` (status "running" until the end)
  and ``particles.pvd`` are
  rewritten after every frame, in that order, so they never reference a frame that is not complete
  on disk, and each is at least as new as the next (killed between two renames, energy.csv may
  hold a step more than summary.json, whose t_final is never behind the last frame listed).
- a lock (``fcntl.flock`` on ``.skdgmpm.lock`` in the folder) is held for the whole run: a second
  run into the same folder is refused with a one-line error naming the running one (pid, host,
  start). The kernel drops the lock when its process dies, SIGKILL included, so a stale lock file
  never blocks anyone.
- nothing outside the folder is touched; inside it, a user's files are only removed with
  ``--force`` (after the lock is taken, so never under a running run).
"""
import errno
import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path

from .errors import InputError, OutputError

LOCK = ".skdgmpm.lock"


def temporary_name(path):
    """The hidden name a file is written under before it is renamed to ``path`` (same suffix, so
    writers that go by it, meshio and matplotlib, pick the same format)."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


def atomic_write(path, write):
    """``write(temporary path)``, then rename it to ``path`` (atomic on POSIX): never half a file."""
    path = Path(path)
    tmp = temporary_name(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise


def write_text(path, text):
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))


def _holder(lock_path):
    """Who holds the lock on ``lock_path`` ("pid 123 on host, started ..."), or None if nobody."""
    try:
        fd = os.open(lock_path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _describe(lock_path)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None                           # a stale file: its run is gone
    finally:
        os.close(fd)


def _describe(lock_path):
    try:
        info = json.loads(Path(lock_path).read_text() or "{}")
    except (OSError, ValueError):
        info = {}
    if not info:
        return "another process"
    return (f"skdgmpm run, pid {info.get('pid')} on {info.get('host')}, started {info.get('started')}"
            + (f": {info['command']}" if info.get("command") else ""))


def _busy(out, holder):
    return InputError(f"--out {out}: in use by another run ({holder}); wait for it to end, or choose "
                      "another --out")


def numbered(base):
    """The default output folder of a command given no ``--out``: ``base`` (e.g. runs/SCENE) if it
    does not exist or is an empty folder, else the first free ``base-2``, ``base-3``, ... Running
    the same command again never touches an earlier run's (or anyone's) files; nothing is created
    here (a run refused for bad input writes nothing)."""
    base = Path(base)
    k = 1
    while True:
        path = base if k == 1 else base.with_name(f"{base.name}-{k}")
        if not path.exists() or (path.is_dir() and not any(path.iterdir())):
            return path
        k += 1


def check(out, force=False, resume=False):
    """Refuse ``out`` before anything is computed or written: not a folder, locked by a running
    run, or (unless ``force`` or ``resume``) not empty. Creates nothing."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: exists and is not a directory")
    parent = next((p for p in out.parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise InputError(f"--out {out}: {parent} is a file, not a directory")
    if not out.exists():
        return
    holder = _holder(out / LOCK)
    if holder is not None:
        raise _busy(out, holder)
    if not force and not resume and any(p.name != LOCK for p in out.iterdir()):
        raise InputError(f"--out {out}: directory exists and is not empty (use --force to replace it)")


class OutputFolder:
    """The locked output folder of one run (a context manager: the lock is released on exit)."""

    def __init__(self, out):
        self.path = Path(out)
        self._fd = None

    def acquire(self, force=False, resume=False):
        """Create the folder if needed, take its lock (refused if another run holds it), then,
        with ``force``, empty it. OSError while creating -> one-line InputError (exit 2)."""
        out = self.path
        check(out, force, resume)
        try:
            out.mkdir(parents=True, exist_ok=True)
            fd = self._lock(out / LOCK)
        except OSError as exc:
            raise InputError(f"--out {out}: cannot create the output folder ({_reason(exc)})") from None
        if fd is None:
            raise _busy(out, _describe(out / LOCK))
        self._fd = fd
        info = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%d %H:%M:%S"), "command": " ".join(sys.argv)}
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps(info).encode())
        if not resume and any(p.name != LOCK for p in out.iterdir()):
            if not force:                 # filled between check() and the lock
                self.release()
                raise InputError(f"--out {out}: directory exists and is not empty (use --force to replace it)")
            for p in out.iterdir():
                if p.name != LOCK:
                    _remove(p)
        return self

    @staticmethod
    def _lock(path):
        """An fd holding an exclusive flock on ``path``, or None if another process holds it."""
        while True:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                return None
            try:                          # the holder may have released (unlinked) it meanwhile
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                return fd
            os.close(fd)

    def release(self):
        if self._fd is None:
            return
        try:
            (self.path / LOCK).unlink()       # while still holding it (see `_lock`)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _remove(path):
    import shutil
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def _reason(exc):
    return exc.strerror or str(exc) if isinstance(exc, OSError) else str(exc)


def write_error(out, what, exc, kept):
    """The one-line OutputError for an OSError while writing ``what`` into ``out``."""
    reason = _reason(exc)
    if getattr(exc, "errno", None) in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
        reason += " (free some space and resume)"
    return OutputError(f"--out {out}: could not write {what}: {reason}; {kept}")


class WriteFailed(Exception):
    """An OSError while writing ``what`` (turned into a one-line `OutputError` by the run)."""

    def __init__(self, what, exc):
        super().__init__(what)
        self.what, self.exc = what, exc


class RunWriter:
    """Writes a run's outputs into its locked folder so that they are consistent at every moment:
    a frame is renamed into place, then ``publish`` rewrites energy.csv, summary.json and last the
    ``.pvd`` that lists the frames (each renamed into place)."""

    def __init__(self, out, stepper, fields=None):
        self.out, self.stepper, self.fields = Path(out), stepper, fields      # fields: of the frames
        self.published_t = None           # time of the last frame that the .pvd lists
        self.checkpointed = None          # step of the last checkpoint written
        self.done = False                 # everything but the plots written at the end

    def _write(self, what, fn):
        try:
            return fn()
        except OSError as exc:
            raise WriteFailed(what, exc) from None

    def grid(self, grid):
        from . import output
        self._write("grid.vtu", lambda: atomic_write(self.out / "grid.vtu", lambda p: output.write_grid(p, grid)))

    def frame(self, index, state):
        from . import output
        name = f"particles_{index:04d}.vtu"
        self._write(name, lambda: atomic_write(self.out / name,
                                               lambda p: output.write_particles(p, self.stepper, state,
                                                                                self.fields)))
        return name

    def publish(self, entries, history, summary, probes=None):
        from . import output
        self._write("energy.csv", lambda: atomic_write(self.out / "energy.csv",
                                                       lambda p: output.write_energy(p, history)))
        if probes is not None:
            self._write("probes.csv", lambda: atomic_write(self.out / "probes.csv", probes.write_csv))
        self._write("summary.json", lambda: atomic_write(self.out / "summary.json",
                                                         lambda p: output.write_summary(p, summary)))
        pvd = [(t, name) for t, name, *_ in entries]
        self._write("particles.pvd", lambda: atomic_write(self.out / "particles.pvd",
                                                          lambda p: output.write_pvd(p, pvd)))
        self.published_t = entries[-1][0] if entries else None
        self.done = summary.get("status") != "running"

    def checkpoint(self, write, step):
        from .checkpoint import NAME
        self._write(NAME, write)
        self.checkpointed = step

    def plots(self, result):
        from .run import _plots
        self._write("the plots (PNG)", lambda: _plots(result, self.out, atomic_write))

    def remove_checkpoint(self):
        from .checkpoint import NAME
        self._write(NAME, lambda: (self.out / NAME).unlink(missing_ok=True))

    def error(self, failed):
        """The one-line `OutputError` for a `WriteFailed`: what failed, what is kept."""
        if self.done:
            kept = "every other output is complete"
        elif self.published_t is None:
            kept = "nothing was kept"
        else:
            kept = f"the outputs up to t = {self.published_t:.6g} s are kept"
            if self.checkpointed is not None:
                kept += (f"; resume from the checkpoint of step {self.checkpointed} with: "
                         f"skdgmpm run --resume {self.out}")
        return write_error(self.out, failed.what, failed.exc, kept)
