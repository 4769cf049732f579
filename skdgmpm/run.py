"""Run a scene: time loop with progress, energy history, error norms, outputs on disk."""
import functools
import shutil
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import output
from .build import build
from .errors import InputError, InstabilityError
from .exact import error_norms
from .scene import Scene, exact_solution, load_scene


@functools.lru_cache(maxsize=32)
def _critical_cfl(layout, integrator):
    from .stability import critical_cfl
    return critical_cfl(list(layout), integrator, criterion="spectral")


def check_cfl(disc):
    """Warn when the CFL exceeds the von Neumann limit of the particle layout (R18 §6).

    The 1D analysis applies per direction; in 2D it is an upper bound (DCU needs less).
    Returns the limit, or None where the layout is not a regular per-cell layout.
    """
    if disc.layout is None:
        return None
    stepper = disc.stepper
    coords = tuple(float(c) for c in np.unique(np.round(disc.layout[:, 0], 12)))
    limit = _critical_cfl(coords, stepper.integrator)
    if stepper.cfl > limit + 1e-6:
        warnings.warn(f"{disc.scene.where('method.cfl')} = {stepper.cfl} exceeds the von Neumann "
                      f"limit {limit:.2f} of layout {list(coords)} with {stepper.integrator} "
                      f"(skdgmpm stability --layout ...)", stacklevel=3)
    return limit


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
            "order": int(getattr(st, "order", 1)), "integrator": st.integrator, "transverse": st.transverse,
            "cfl": st.cfl, "dim": s.dim, "cells": int(st.grid.submesh.nelements),
            "grid_cells": int(st.grid.mesh.nelements), "particles": len(self.disc.particles),
            "dofs": int(st.n_dofs_total), "steps": int(self.state.step),
            "t_end": float(s.get("run.t_end")), "t_final": float(self.state.t),
            "startup_s": self.startup_s, "wall_s": self.wall_s,
            "wall_per_step_s": self.wall_s / max(self.state.step - 1, 1),
            "status": self.status,
        }
        if self.message:
            out["message"] = self.message
        picard = getattr(st, "picard", None)
        if picard is not None:
            out["picard"] = {"mean_iterations": picard.mean, "max_iterations": picard.max,
                             "not_converged_steps": picard.not_converged}
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
    fields = output.particle_fields(disc.stepper, state)
    exact = solution.fields(disc.particles.X, state.t)
    return {k: error_norms(fields[k], exact[k], disc.particles.volume)
            for k in exact if k in fields}


def run(scene, overrides=(), out=None, force=False, progress=True, frames=None, max_steps=None,
        on_step=None):
    """Run ``scene`` (a `Scene`, a name or a path). Writes outputs to ``out`` if given.
    ``max_steps`` stops the run early (benchmarks); ``on_step(state, disc)`` is called with the initial
    state and after every step (error measures over the whole run, e.g. WG08's).

    Output is written to ``<out>.partial`` and renamed at the end, so a failed start leaves
    nothing behind; an existing non-empty ``out`` is an error unless ``force``.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene, overrides)
    elif overrides:
        scene = scene.with_overrides(overrides)
    t_end = scene.get("run.t_end")
    if not (isinstance(t_end, (int, float)) and not isinstance(t_end, bool) and 0 < t_end < np.inf):
        raise InputError(f"{scene.where('run.t_end')} = {t_end!r} must be a time > 0 (s)")
    n_frames = int(frames) if frames is not None else scene.get("run.frames", 20)
    if not (isinstance(n_frames, int) and not isinstance(n_frames, bool) and n_frames >= 1):
        raise InputError(f"{scene.where('run.frames')} = {n_frames!r} must be an integer >= 1")
    if out is not None:
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {out}: exists and is not a directory")
        if out.exists() and any(out.iterdir()) and not force:
            raise InputError(f"--out {out}: directory exists and is not empty (use --force to replace it)")
    begin = time.perf_counter()
    disc = build(scene)
    solution = exact_solution(scene)
    check_cfl(disc)
    stepper, state = disc.stepper, disc.initial

    partial = None
    if out is not None:
        partial = out.with_name(out.name + ".partial")
        shutil.rmtree(partial, ignore_errors=True)
        partial.mkdir(parents=True)
    try:
        return _run(scene, disc, solution, stepper, state, t_end, n_frames, out, partial, progress, max_steps,
                    on_step, begin)
    except BaseException:                 # crash or Ctrl-C: leave no half-written output behind
        if partial is not None:
            shutil.rmtree(partial, ignore_errors=True)
        raise


def _run(scene, disc, solution, stepper, state, t_end, n_frames, out, partial, progress, max_steps=None,
         on_step=None, begin=None):
    """The time loop. Timing: ``startup_s`` runs from ``begin`` (before the build) to the end of the
    first step, which compiles the kernels or loads them from numba's cache; ``wall_s`` is the
    rest of the loop, so timings compare methods and grids whatever the state of the cache."""
    if partial is not None:
        output.write_grid(partial / "grid.vtu", disc.grid)

    history = {k: [] for k in ("step", "t", "kinetic", "stored", "dissipated", "total", "external_work",
                               "balance", "min_J", "min_acoustic")}

    def record(st):
        kin, sto, dis = stepper.energy(st)
        total = kin + sto + dis
        for k, v in zip(history, (st.step, st.t, kin, sto, dis, total, stepper.external_work,
                                  total - stepper.external_work)):
            history[k].append(v)
        health = st.health or {}                # run health: set by the stepper's check
        history["min_J"].append(health.get("min_J", np.nan))
        history["min_acoustic"].append(health.get("min_acoustic", np.nan))

    frame_list, entries = [], []

    def snapshot(st):
        frame_list.append(st.copy())
        if partial is not None:
            name = f"particles_{len(entries):04d}.vtu"
            output.write_particles(partial / name, stepper, st)
            entries.append((st.t, name))

    record(state)
    snapshot(state)
    if on_step is not None:
        on_step(state, disc)
    next_frame = 1
    status, message = "ok", ""
    bar = _progress(t_end, scene.name, progress)
    start, warm = time.perf_counter(), None
    try:
        while state.t < t_end * (1 - 1e-12) and (max_steps is None or state.step < max_steps):
            new = stepper.step(state, t_end - state.t)
            bar.update(new.t - state.t)
            state = new
            record(state)
            if on_step is not None:
                on_step(state, disc)
            if state.t >= next_frame * t_end / max(n_frames, 1) * (1 - 1e-12):
                snapshot(state)
                while next_frame * t_end / max(n_frames, 1) <= state.t * (1 + 1e-12):
                    next_frame += 1
            if warm is None:                      # the first step done: the kernels are compiled
                warm = time.perf_counter()
    except InstabilityError as exc:
        status, message = "unstable", str(exc)
        if exc.step is None:              # raised on a face (Riemann solver), not on a particle
            message += f" during step {state.step + 1} (from t = {state.t:.6g} s)"
        if frame_list[-1].step != state.step:
            snapshot(state)                       # the last good state
    finally:
        bar.close()
    end = time.perf_counter()
    warm = end if warm is None else warm
    wall, startup = end - warm, warm - (start if begin is None else begin)
    history = {k: np.asarray(v) for k, v in history.items()}
    result = Result(scene, disc, state, history, frame_list,
                    compute_errors(disc, state, solution), wall, status, message, out, solution, startup)
    if partial is not None:
        output.write_pvd(partial / "particles.pvd", entries)
        output.write_energy(partial / "energy.csv", history)
        output.write_summary(partial / "summary.json", result.summary())
        _plots(result, partial)
        if out.exists():
            shutil.rmtree(out)
        partial.rename(out)
    return result


def _plots(result, folder):
    try:
        from . import plots
    except ImportError:          # matplotlib missing: files are still complete
        return
    plots.energy(result, folder / "energy.png")
    if result.scene.dim == 1 or result.exact is not None:
        plots.profile(result, folder / "profile.png")
    if "eqp" in result.fields():                # a law with plastic flow: where it flowed
        if result.scene.dim == 1:
            plots.profile(result, folder / "eqp.png", field="eqp")
        else:
            plots.field_map(result, "eqp", folder / "eqp.png")


class _NoBar:
    def set_description(self, _):
        pass

    def update(self, n=1):
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
    return progress_bar(enabled, total, desc=name, unit="s",
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| t={n:.3g}/{total:.3g} s [{elapsed}<{remaining}]")
