"""Run a scene: time loop with progress, energy history, error norms, outputs on disk."""
import signal
import sys
import threading
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba.core import event

from . import checkpoint, compile_helper, guards, outdir, output, parallel, probes as gauges
from .build import build
from .errors import InputError, InstabilityError, OutputError
from .exact import relative_errors
from .first_run import compile_notice
from .scene import Scene, exact_solution, load_scene


@dataclass
class Result:
    """A finished (or stopped) run: final state, history, frames, errors and summary."""

    scene: Scene
    disc: object
    state: object
    history: dict
    frames: list
    errors: dict
    wall_s: float                 # the time loop without its first step (see startup_s)
    status: str = "ok"
    message: str = ""
    out: Path = None
    exact: object = field(default=None, repr=False)
    startup_s: float = 0.0        # build, initial state and the first step (compiles or loads the kernels)
    probes: object = field(default=None, repr=False)   # skdgmpm.probes.Probes: the gauges' histories

    @property
    def stepper(self):
        return self.disc.stepper

    @property
    def X(self):
        return self.disc.particles.X

    def fields(self, state=None):
        return output.particle_fields(self.stepper, state or self.state)

    def summary(self):
        s, st = self.scene, self.stepper
        method = s.data["method"]
        out = {
            "case": s.name, "title": s.get("title", ""), "method": method.get("name", "dgmpm"),
            "order": int(getattr(st, "order", 1)), "integrator": st.integrator,
            "transverse": st.transverse if s.dim > 1 or method.get("name", "dgmpm") != "dgmpm" else "none",
            "cfl": st.cfl, "dim": s.dim, "cells": int(st.grid.submesh.nelements),
            "grid_cells": int(st.grid.mesh.nelements), "particles": len(self.disc.particles),
            "dofs": int(st.n_dofs_total), "steps": int(self.state.step),
            "t_end": float(s.get("run.t_end")), "t_final": float(self.state.t),
            "startup_s": self.startup_s, "wall_s": self.wall_s,
            "wall_per_step_s": self.wall_s / max(self.state.step - 1, 1),
            "threads": parallel.threads(), "status": self.status,
        }
        if self.message:
            out["message"] = self.message
        if self.disc.cfl_default:
            out["cfl_default"] = self.disc.cfl_default
        picard = getattr(st, "picard", None)
        if picard is not None:
            # per step: the most iterations of a cell (each cell stops at its own convergence)
            out["picard"] = {"mean_iterations": picard.mean, "max_iterations": picard.max,
                             "mean_cell_iterations": picard.cell_mean, "not_converged_steps": picard.not_converged}
        health = ("min_J", "min_acoustic")
        energy = {k: float(v[-1]) for k, v in self.history.items() if k not in ("step", "t", *health)}
        energy["balance_change"] = float(self.history["balance"][-1] - self.history["balance"][0])
        out["energy"] = energy
        out["health"] = {f"{k}_min": float(np.nanmin(self.history[k])) if np.isfinite(self.history[k]).any()
                         else None for k in health}
        if self.errors:
            out["errors"] = self.errors
        return out

    def plot(self, field="P11", time=None, grid=True, path=None, **options):
        """Particles at ``time`` (default: the end) coloured by ``field``, over the grid: a
        picture shown inline in Jupyter, written to ``path`` (PNG) if given. See `pictures`."""
        from . import pictures
        return pictures.particles(self, field, time, grid, path, **options)

    def plot_line(self, field="P11", time=None, **options):
        """``field`` along a segment (default: the bottom line) against the exact solution;
        ``start``, ``end``, ``path``, ``ax``, ``label``, ``exact``: see `pictures.line`."""
        from . import pictures
        return pictures.line(self, field, time, **options)

    def animate(self, path, field="P11", **options):
        """The stored frames as a GIF (or MP4) at ``path``; shown inline in Jupyter."""
        from . import pictures
        return pictures.animate(self, path, field, **options)

    def __repr__(self):
        """One line: scene, method, steps, time, wall time, status and the headline errors."""
        st, method = self.stepper, self.summary()["method"]
        if method != "dgmpm" and hasattr(st, "order"):
            method += f" P{st.order}"
        options = [st.integrator] + ([st.transverse] if self.scene.dim > 1 and getattr(st, "transverse", None)
                                     not in (None, "none") else [])
        err = ""
        if self.errors:
            l2 = {k: v["L2_rel"] for k, v in self.errors.items()}
            shown = [k for k in ("P11", "v1") if k in l2] or list(l2)[:2]
            worst = max(l2, key=l2.get)
            err = "; L2 rel " + ", ".join(f"{k} {l2[k]:.2e}" for k in shown)
            if l2[worst] > 1.01 * max(l2[k] for k in shown):
                err += f" (max {worst} {l2[worst]:.2e})"
        return (f"<Result {self.scene.name}: {method} ({', '.join(options)}), {self.status}, "
                f"{self.state.step} steps to t = {self.state.t:.4g} s in {self.wall_s:.2f} s{err}>")


def compute_errors(disc, state, solution):
    if solution is None:
        return {}
    exact = solution.fields(disc.particles.X, state.t)
    fields = output.particle_fields(disc.stepper, state, names=tuple(exact))
    return relative_errors(fields, exact, disc.particles.volume)


def run(scene=None, overrides=(), out=None, force=False, progress=True, frames=None, max_steps=None,
        on_step=None, resume=None, signals=None, notice=None):
    """Run ``scene`` (a `Scene`, a name or a path). Writes outputs to ``out`` if given.
    ``max_steps`` stops the run early (benchmarks); ``on_step(state, disc)`` is called with the initial
    state and after every step (error measures over the whole run, e.g. WG08's).

    Outputs go straight into ``out``, locked against other runs and consistent at every moment
    (`skdgmpm.outdir`); an existing non-empty ``out`` is an error unless ``force``, and input
    errors are raised before anything is written. With ``out``, a checkpoint is written every
    ``run.checkpoint_every`` (`skdgmpm.checkpoint`) and, when ``signals`` (default: with ``out``, in
    the main thread), on SIGINT or SIGTERM, after which the run returns with status "interrupted".
    ``resume=DIR`` continues the run checkpointed in DIR (no scene or overrides: the run goes on
    with the scene it started with), its outputs bit-identical to an uninterrupted run's.
    ``notice`` (default: ``progress``): say on stderr, in one line, when the kernels compile.
    """
    saved = None
    if resume is not None:
        if scene is not None or overrides:
            raise InputError("--resume: give no scene and no --set: the run goes on with the scene it started with")
        if out is not None and Path(out).resolve() != Path(resume).resolve():
            raise InputError(f"--resume {resume} writes into {resume}, not --out {out}")
        out = Path(resume)
        outdir.check(out, resume=True)
        saved = checkpoint.read(out)
        scene = Scene.from_dict(saved.scene_data, saved.scene_name,
                                Path(saved.scene_path) if saved.scene_path else None)
        scene.overridden = saved.scene_overridden
        n_frames = saved.n_frames
    elif scene is None:
        raise InputError("no scene given (a name from 'skdgmpm list' or a .toml path), nor --resume DIR")
    elif not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        scene = scene.with_overrides(overrides)
    t_end, steps = scene.get("run.t_end"), scene.get("run.steps")
    if steps is not None and t_end is not None and "run.t_end" in scene.overridden:
        steps = None                        # --set run.t_end fixes the time instead
    if steps is not None:
        if t_end is not None:
            raise InputError(f"{scene.where('run.steps')} = {steps!r} and {scene.where('run.t_end')} = {t_end!r}: "
                             "give one of them (run.steps sets the end time from the first time step)")
        if not (steps == "cells" or (isinstance(steps, int) and not isinstance(steps, bool) and steps >= 1)):
            raise InputError(f"{scene.where('run.steps')} = {steps!r} must be a whole number of steps >= 1 or "
                             "\"cells\" (as many steps as cells along X, L23 §5.1's N_t = N_e)")
    elif not (isinstance(t_end, (int, float)) and not isinstance(t_end, bool) and 0 < t_end < np.inf):
        raise InputError(f"{scene.where('run.t_end')} = {t_end!r} must be a time > 0 (s)")
    if saved is None:
        n_frames = int(frames) if frames is not None else scene.get("run.frames", 20)
        if not (isinstance(n_frames, int) and not isinstance(n_frames, bool) and n_frames >= 1):
            raise InputError(f"{scene.where('run.frames')} = {n_frames!r} must be an integer >= 1")
    every = checkpoint.parse_every(scene)
    guards.step_limit(scene)
    threads = scene.get("run.threads")
    if threads is not None and not (isinstance(threads, int) and not isinstance(threads, bool) and threads >= 1):
        raise InputError(f"{scene.where('run.threads')} = {threads!r} must be a whole number >= 1 (threads of "
                         f"the compiled passes; default: every core)")
    if out is not None:
        out = Path(out)
        outdir.check(out, force, resume=saved is not None)
    begin = time.perf_counter()
    show = progress if notice is None else notice
    # on the first compilation, one or two more processes compile the rest of the step meanwhile
    helper = compile_helper.CompileHelpers(scene, saved is not None) if compile_helper.wanted(scene) else None
    kind = scene.get("method.name", "dgmpm") + (" on the nodes" if compile_helper.nodal(scene) else "")
    notice = (compile_notice(kind, scene.dim, on_first=helper and helper.start, show=show) if show or helper
              else nullcontext())
    try:
        with notice:                      # a line on stderr if the kernels are not in the cache
            disc = build(scene)           # its initial state takes the step's law pass, beside the helper
        if steps is not None:             # the end time of that many first time steps [L23 eq 67]
            scene, t_end = _end_of_steps(scene, disc, steps)
        solution = exact_solution(scene)
        guards.check_cfl(disc)
        if disc.cfl_default and progress:
            print(f"note: method.cfl not set: {disc.stepper.cfl}, {disc.cfl_default}", file=sys.stderr)
        guards.check_step_count(disc, t_end)
        if helper is not None:            # its kernels into the cache before the first step
            helper.join()
            if hasattr(notice, "seconds"):
                notice.seconds += helper.waited
    finally:
        if helper is not None:
            helper.close()
    stepper, state = disc.stepper, disc.initial
    fields = output.frame_fields(scene, stepper)
    probes = gauges.from_scene(scene, disc)
    if saved is not None:
        state = saved.state
        checkpoint.restore_stepper(stepper, saved.stepper)

    folder = None if out is None else outdir.OutputFolder(out).acquire(force, resume=saved is not None)
    if signals is None:
        signals = out is not None and threading.current_thread() is threading.main_thread()
    previous = parallel.set_threads(threads) if threads is not None else None
    try:
        with notice:
            return _run(scene, disc, solution, stepper, state, t_end, n_frames, out, progress, max_steps,
                        on_step, begin, saved=saved, every=every, signals=signals, fields=fields,
                        probes=probes)
    finally:
        if threads is not None:
            parallel.set_threads(previous)
        if folder is not None:
            folder.release()


def _end_of_steps(scene, disc, steps):
    """The scene with ``run.t_end`` = steps x the first time step in place of ``run.steps``
    ("cells": as many steps as cells along X), and that end time."""
    if steps == "cells":
        cells = scene.get("grid.cells")
        if cells is None or scene.get("grid.mesh") is not None:
            raise InputError(f"{scene.where('run.steps')} = 'cells' needs grid.cells (a structured grid)")
        steps = int(cells if isinstance(cells, int) else cells[0])
    t_end = steps * float(disc.stepper.time_step(disc.initial))
    scene = scene.with_overrides([f"run.t_end={t_end!r}"])
    del scene.data["run"]["steps"]
    return scene, t_end


def resume(folder, progress=True, signals=None, notice=None):
    """Continue the run checkpointed in ``folder`` (what ``skdgmpm run --resume DIR`` does)."""
    return run(resume=folder, progress=progress, signals=signals, notice=notice)


class _Signals:
    """Within the block, SIGINT and SIGTERM only set ``caught`` (the loop then checkpoints and
    stops); a second SIGINT raises KeyboardInterrupt at once. Outside the main thread: nothing."""

    NAMES = {signal.SIGINT: "SIGINT", signal.SIGTERM: "SIGTERM"}

    def __init__(self, enabled):
        self.enabled, self.caught, self.old = enabled, None, {}

    def _handler(self, signum, frame):
        if self.caught == signal.SIGINT and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.caught = signum

    def __enter__(self):
        if self.enabled:
            self.old = {s: signal.signal(s, self._handler) for s in self.NAMES}
        return self

    def __exit__(self, *exc):
        for s, handler in self.old.items():
            signal.signal(s, handler)


HISTORY = ("step", "t", "kinetic", "stored", "dissipated", "total", "external_work", "balance", "min_J",
           "min_acoustic")


def _run(scene, disc, solution, stepper, state, t_end, n_frames, out, progress, max_steps=None,
         on_step=None, begin=None, saved=None, every=None, signals=False, fields=None,
         probes=None):
    """The time loop. Timing: ``startup_s`` runs from ``begin`` (before the build) to the end of the
    first step, which compiles the kernels or loads them from numba's cache; ``wall_s`` is the
    rest of the loop, so timings compare methods and grids whatever the state of the cache. A
    kernel compiled inside the loop (a path the first step did not take) counts in the start-up
    too, not in ``wall_s`` (`CompileClock`)."""
    writer = None if out is None else outdir.RunWriter(out, stepper, fields)
    if saved is None:
        history = {k: [] for k in HISTORY}
        entries, next_frame, frame_list = [], 1, []
    else:
        history, entries, next_frame = saved.history, list(saved.entries), saved.next_frame
        if probes is not None:
            probes.restore(saved.probes)
        frame_list = [output.read_frame(out / name, stepper, t, step) for t, name, step in entries]
    energy_guard = guards.EnergyGuard(stepper, history)
    energy_every = guards.energy_every(scene, stepper)
    step_guard = guards.StepGuard(scene, None if saved is None else saved.dt0)

    def record(st, energies=None):
        kin, sto, dis = stepper.energy(st) if energies is None else energies
        total = kin + sto + dis
        for k, v in zip(history, (st.step, st.t, kin, sto, dis, total, stepper.external_work,
                                  total - stepper.external_work)):
            history[k].append(v)
        health = st.health or {}                # run health: set by the stepper's check
        history["min_J"].append(health.get("min_J", np.nan))
        history["min_acoustic"].append(health.get("min_acoustic", np.nan))

    def snapshot(st):
        frame_list.append(st.copy())
        if writer is not None:
            entries.append((st.t, writer.frame(len(entries), st), st.step))

    def make_result(status, message, errors=None, wall=0.0, startup=0.0):
        return Result(scene, disc, state, {k: np.asarray(v) for k, v in history.items()}, frame_list,
                      errors or {}, wall, status, message, out, solution, startup, probes)

    def publish(status="running", message="", errors=None, wall=0.0, startup=0.0):
        if writer is not None:
            writer.publish(entries, history, make_result(status, message, errors, wall, startup).summary(), probes)

    def save_checkpoint(wall, startup):
        writer.checkpoint(lambda: checkpoint.write(out, scene, state, stepper, history, entries, next_frame,
                                                   n_frames, wall, startup, step_guard.dt0, probes), state.step)

    wall0 = 0.0 if saved is None else saved.wall_s
    startup0 = 0.0 if saved is None else saved.startup_s
    if saved is None:
        if writer is not None:
            writer.grid(disc.grid)
        record(state)
        if probes is not None:
            probes.record(stepper, state)
        energy_guard.check(state, history["total"][-1], stepper.external_work)
        snapshot(state)
        publish()
    if on_step is not None and saved is None:
        on_step(state, disc)
    status, message, stopped = "ok", "", None
    schedule = checkpoint.Schedule(every, state.step) if writer is not None else None
    bar = _progress(t_end, scene.name, progress)
    if saved is not None:
        bar.update(state.t)
    start, warm, compiling = time.perf_counter(), None, CompileClock()

    def timing(now):
        w = now if warm is None else warm
        late = compiling.seconds if warm is not None else 0.0       # compiled after the first step
        return wall0 + now - w - late, startup0 + w - (start if begin is None else begin) + late

    try:
        with _Signals(signals) as caught, event.install_listener("numba:compile", compiling):
            try:
                while state.t < t_end * (1 - 1e-12) and (max_steps is None or state.step < max_steps):
                    new = stepper.step(state, t_end - state.t)
                    if warm is None:
                        bar.unpause()             # the first step compiles: its time is not in the rate
                    step_guard.check(state, new, t_end)
                    frame_due = new.t >= next_frame * t_end / max(n_frames, 1) * (1 - 1e-12)
                    # a row of energy.csv (and the balance's check) on steps fixed by the scene alone,
                    # so that a resumed run writes the rows an uninterrupted one does
                    energies = None
                    if (new.step % energy_every == 0 or frame_due or new.t >= t_end * (1 - 1e-12)
                            or new.step == max_steps):
                        energies = stepper.energy(new)
                        energy_guard.check(new, sum(energies), stepper.external_work)
                    bar.update(new.t - state.t)
                    state = new
                    if energies is not None:
                        record(state, energies)
                    if probes is not None and (probes.due(state.step) or state.t >= t_end * (1 - 1e-12)
                                               or state.step == max_steps):
                        probes.record(stepper, state)
                    if on_step is not None:
                        on_step(state, disc)
                    if frame_due:
                        snapshot(state)
                        while next_frame * t_end / max(n_frames, 1) <= state.t * (1 + 1e-12):
                            next_frame += 1
                        publish()
                    if warm is None:                      # the first step done: the kernels are compiled
                        warm, compiling.seconds = time.perf_counter(), 0.0
                    if caught.caught is not None:
                        stopped = caught.NAMES[caught.caught]
                        break
                    if schedule is not None and schedule.due(state.step):
                        save_checkpoint(*timing(time.perf_counter()))
                        publish()
                        schedule.done(state.step)
            except InstabilityError as exc:
                status, message = "unstable", str(exc)
                if exc.step is None:              # raised on a face (Riemann solver), not on a particle
                    message += f" during step {state.step + 1} (from t = {state.t:.6g} s)"
                if frame_list[-1].step != state.step:
                    snapshot(state)                       # the last good state
            finally:
                bar.close()
            end = time.perf_counter()
            wall, startup = timing(end)
            if stopped is not None:
                status = "interrupted"
                message = f"stopped by {stopped} at step {state.step}, t = {state.t:.6g} s of {t_end:.6g} s"
                if writer is not None:
                    save_checkpoint(wall, startup)
                    message += f"; checkpoint written, resume with: skdgmpm run --resume {out}"
            result = make_result(status, message, compute_errors(disc, state, solution) if status != "interrupted"
                                 else {}, wall, startup)
            if writer is not None:
                writer.publish(entries, history, result.summary(), probes)
                if status != "interrupted":
                    writer.plots(result)
                if status == "ok":
                    writer.remove_checkpoint()
    except outdir.WriteFailed as exc:
        raise writer.error(exc) from None
    except BaseException as exc:          # a bug, a second Ctrl-C: what is on disk stays consistent
        if writer is not None and not isinstance(exc, OutputError):
            try:
                publish("failed", f"{type(exc).__name__}: {exc}")
            except Exception:
                pass
        raise
    return result


class CompileClock(event.Listener):
    """Wall seconds this thread spends compiling (numba's outermost "numba:compile" events; a
    kernel loaded from the cache is not one) while installed: `_run` moves those of the timed
    loop into the start-up. Each outermost compilation goes to `compiled` (bench/late_compiles.py
    records them by step)."""

    def __init__(self):
        self.seconds, self.depth, self.start, self.thread = 0.0, 0, 0.0, threading.get_ident()

    def on_start(self, ev):
        if threading.get_ident() == self.thread:
            self.depth += 1
            if self.depth == 1:
                self.start, self.event = time.perf_counter(), ev

    def on_end(self, ev):
        if threading.get_ident() == self.thread:
            self.depth -= 1
            if self.depth == 0:
                self.compiled(time.perf_counter() - self.start, self.event)

    def compiled(self, seconds, ev):
        """One outermost compilation of ``seconds``; ``ev``: the event that began it."""
        self.seconds += seconds


def _plots(result, folder, atomic=None):
    """energy.png, profile.png (always; against the exact solution when there is one), probes.png
    (with [probes]) and eqp.png (a law with plastic flow) into ``folder``; each written
    through ``atomic(path, write)`` if given (`outdir.atomic_write`: never half a PNG)."""
    try:
        from . import plots
    except ImportError:          # matplotlib missing: files are still complete
        return
    atomic = atomic or (lambda path, write: write(path))
    atomic(folder / "energy.png", lambda p: plots.energy(result, p))
    atomic(folder / "profile.png", lambda p: plots.profile(result, p))     # with the exact solution if any
    if result.probes is not None:
        atomic(folder / "probes.png", lambda p: plots.probes(result, p))
    if "eqp" in result.fields():                # a law with plastic flow: where it flowed
        if result.scene.dim == 1:
            atomic(folder / "eqp.png", lambda p: plots.profile(result, p, field="eqp"))
        else:
            atomic(folder / "eqp.png", lambda p: plots.field_map(result, "eqp", p))


class _NoBar:
    def set_description(self, _):
        pass

    def update(self, n=1):
        pass

    def unpause(self):
        pass

    def close(self):
        pass


def progress_bar(enabled, total, **options):
    """A tqdm bar on stderr (notebook widget in Jupyter), or a silent stand-in."""
    if not enabled:
        return _NoBar()
    from tqdm.auto import tqdm
    return tqdm(total=total, file=sys.stderr, leave=False, **options)


def _progress(total, name, enabled):
    # delay: a run shorter than a second draws no bar, so leaves no cleared bar line (a blank line
    # in a log or a notebook's `!skdgmpm run`) before its summary
    return progress_bar(enabled, total, desc=name, unit="s", delay=1.0,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| t={n:.3g}/{total:.3g} s [{elapsed}<{remaining}]")
