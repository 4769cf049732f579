"""Command line: ``skdgmpm run | list | scenes | stability | converge | compare | bench | cfl-limit | compare-figures``."""
import argparse
import json
import sys
import warnings

from .errors import InputError, OutputError


# exit statuses of `skdgmpm run` (sysexits.h names where one fits)
EXIT_INPUT = 2           # bad input: one line naming file, key and value; nothing written
EXIT_UNSTABLE = 3        # a health stop: the last good state kept
EXIT_OUTPUT = 74         # EX_IOERR: the outputs could not be written (full disk, ...); what was written kept
EXIT_INTERRUPTED = 75    # EX_TEMPFAIL: stopped by SIGINT or SIGTERM after a checkpoint; --resume goes on
EXIT_BROKEN_PIPE = 141   # 128 + SIGPIPE, as a tool the shell's pipe closed on: `skdgmpm list | head -1`


def _cmd_run(args):
    from . import parallel
    from .run import run

    if args.threads is not None:
        if args.threads < 1:
            raise InputError(f"--threads {args.threads}: expected a whole number >= 1")
        parallel.set_threads(args.threads)      # the scene's run.threads, if set, wins
    if args.resume is not None:
        if args.case is not None or args.set or args.force:
            raise InputError(f"--resume {args.resume}: give no scene, --set or --force: the run goes on with "
                             "the scene it started with")
        out = args.resume
        result = run(resume=args.resume, out=args.out, progress=not args.quiet, notice=True)
    else:
        if args.case is None:
            raise InputError("run: give a scene (a name from 'skdgmpm list' or a .toml path), or --resume DIR")
        out = _out_dir(args, f"runs/{_stem(args.case)}", check=False)
        result = run(args.case, overrides=args.set, out=out, force=args.force and args.out is not None,
                     progress=not args.quiet, notice=True)     # --quiet: no bar, but say when it compiles
    summary = result.summary()
    print(f"{summary['case']}: {summary['status']}, {summary['steps']} steps to t = "
          f"{summary['t_final']:.6g} s in {summary['wall_s']:.2f} s (+ {summary['startup_s']:.2f} s start-up) "
          f"-> {out}")
    for name, norms in summary.get("errors", {}).items():
        ref = norms.get("relative_to", name)
        scale = "" if ref == name else " (absolute: exact 0)" if ref is None else f" (relative to {ref})"
        print(f"  {name:>6}: L1_rel {norms['L1_rel']:.3e}  L2_rel {norms['L2_rel']:.3e}  "
              f"Linf {norms['Linf']:.3e}{scale}")
    if result.status == "interrupted":
        print(result.message, file=sys.stderr)
        return EXIT_INTERRUPTED
    if result.status != "ok":
        print(f"error: {result.message}; last good state kept in {out}", file=sys.stderr)
        return EXIT_UNSTABLE
    return 0


def _stem(case):
    from pathlib import Path
    return Path(case).stem


def _cmd_list(args):
    from .scene import list_scenes, load_scene

    for name, path in list_scenes().items():
        scene = load_scene(path)
        print(f"{name:<28} {scene.dim}D  {scene.get('title', '')}  [{scene.get('reference', '')}]")
    return 0


def _cmd_cache(args):
    from . import cache_folders, kernel_cache

    base = kernel_cache.cache_base()
    if args.prune:
        removed, failed = cache_folders.prune(base)
        for path, size in removed:
            print(f"removed {path}  ({size / 2 ** 20:.1f} MiB)")
        for path, reason in failed:
            print(f"warning: could not remove {path}: {reason}", file=sys.stderr)
        print(f"{len(removed)} folder(s) removed, {sum(size for _, size in removed) / 2 ** 20:.1f} MiB; "
              f"kept {kernel_cache.cache_dir()}")
        return 0
    print(f"compiled kernels under {base} (these sources: {kernel_cache.cache_dir()})")
    for line in cache_folders.report(cache_folders.folders(base)):
        print(line)
    return 0


def _cmd_scenes(args):
    from . import scene_keys
    from .scene import copy_scene, find_scene

    if args.action == "show":
        path = find_scene(args.name)
        sys.stdout.write(f"# {path}\n" + path.read_text(encoding="utf-8"))
    elif args.action == "copy":
        written = copy_scene(args.name, args.dir, force=args.force)
        print(f"copied {', '.join(str(p) for p in written)}\nrun it with: skdgmpm run {written[0]}")
    else:
        sys.stdout.write(scene_keys.markdown() if args.markdown else scene_keys.text() + "\n")
    return 0


def _cmd_stability(args):
    from .stability import analyse, parse_layout

    if args.dim == 2 or args.method != "dgmpm":
        return _stability_of_steps(args)
    if args.layout is None:
        raise InputError("skdgmpm stability: --layout is required in 1D (e.g. --layout 0.25,0.75)")
    layout = parse_layout(args.layout)
    report = analyse(layout)
    print(report.format())
    if args.json:
        print(json.dumps(report.__dict__, default=list))
    return 0


def _stability_of_steps(args):
    from . import stability2d

    if args.per_cell < 1:
        raise InputError(f"skdgmpm stability: --per-cell {args.per_cell} must be a positive integer")
    if not -1.0 < args.nu < 0.5:
        raise InputError(f"skdgmpm stability: --nu {args.nu} must lie in (-1, 0.5)")
    n = args.per_cell
    where = f"{n} x {n} points a cell at (k + 1/2) / {n}; nu = {args.nu:g}" if args.dim == 2 else f"{n} points a cell"
    print(f"{args.method}; {where} (DGMPM, ADER-DGMPM: particles); {args.dim}D linear elasticity (the engine's own "
          f"step, skdgmpm.stability2d; compiles the linear law's step on first use)")
    if args.method == "dgmpm":
        print(f"{'method':<8}{'ctu':>8}{'dcu':>8}")
        report = {}
        for integrator in ("euler", "rk2"):
            row = [stability2d.bracket(n, integrator, t, args.nu) for t in ("ctu", "dcu")]
            report[integrator] = dict(zip(("ctu", "dcu"), (lo for lo, _ in row)))
            print(f"{integrator:<8}" + "".join(f"{stability2d.shown(pair):>8}" for pair in row))
    else:
        method = {"name": args.method, "order": args.order}
        if args.method == "rk-dgfem":
            method["integrator"] = args.integrator or ("rk2" if args.order == 1 else "rk4")
        # a step that grows at every CFL: its knee where the table has one, else its bracket is not a limit
        key = stability2d.dg_key(args.method, args.order, method.get("integrator"))
        growth = stability2d.growth(key)
        pair = stability2d.bracket(n, nu=args.nu if args.dim == 2 else 0.0, hi=2.0, method=method, dim=args.dim,
                                   growth=growth)
        report = {"order": args.order, **method, "cfl": pair[0]}
        print(f"order {args.order}{', ' + method['integrator'] if 'integrator' in method else ''}: "
              f"CFL limit {stability2d.shown(pair)} (the method's CFL: dt = CFL h / ((2P + 1) c) for P >= 1)")
        grows = stability2d.grows_at_every_cfl(args.method, args.order, method.get("integrator"))
        if grows is not None:
            what = "its knee" if key in stability2d.SLOW_GROWTH else "not a limit"
            print(f"  {what}: {grows}; below {pair[0]:.3f} each step grows by at most {growth:g}")
    print("CFL limit: the largest CFL at which no Fourier mode of the step grows (to 0.002, below);")
    print("  skdgmpm run refuses a CFL above it (method.cfl_above_limit = true runs it anyway).")
    if args.json:
        print(json.dumps({"method": args.method, "per_cell": n, "nu": args.nu, "limits": report}))
    return 0


def _study(args, default_out):
    """Run the convergence study of ``converge``/``compare``; returns (rows, out folder)."""
    from . import study
    from .executor import make_executor

    out = _out_dir(args, default_out)
    pool = make_executor(args.workers, dask=args.dask)
    try:
        rows = study.convergence(args.scene, [m for m in args.methods.split(",") if m],
                                 study._int_list(args.orders, "--orders"), study._int_list(args.cells, "--cells"),
                                 overrides=args.set, fields=[f for f in (args.fields or "").split(",") if f] or None,
                                 progress=not args.quiet, reference=args.reference,
                                 cfls=study._float_list(args.cfls, "--cfls") if args.cfls else None,
                                 measure=args.measure, executor=pool)
    finally:
        pool.shutdown()
    out.mkdir(parents=True, exist_ok=True)
    return rows, out


def _cmd_converge(args):
    from . import study

    rows, out = _study(args, f"runs/converge_{_stem(args.scene)}")
    print(study.format_table(rows))
    study.write_csv(out / "convergence.csv", rows)
    study.plot(rows, out)
    sweep = "h" if len({r["cells"] for r in rows}) > 1 else "cfl"
    print(f"-> {out}/convergence.csv, error_vs_{sweep}.png, error_vs_time.png")
    return 0


def _cmd_compare(args):
    from . import study

    rows, out = _study(args, f"runs/compare_{_stem(args.scene)}")
    print(study.format_table(rows))
    column = next((c for c, name in study.error_keys(rows[0]) if name == args.field), None) \
        if args.field else study.error_keys(rows[0])[0][0]
    if column is None:
        raise InputError(f"--field {args.field!r} is not in the study "
                         f"(known: {', '.join(n for _, n in study.error_keys(rows[0]))})")
    study.write_csv(out / "compare.csv", rows)
    study.plot_work_precision(rows, column, out / "work_precision.png",
                              title=f"{_stem(args.scene)}: {column.replace('_', ' ')} against wall time")
    print(f"\nfastest to each accuracy ({column.replace('_', ' ')}):")
    for target, label, seconds in study.winners(rows, column):
        print(f"  {target:9.1e}  {label:<22} {seconds:8.2f} s")
    print(f"-> {out}/compare.csv, work_precision.png")
    return 0


def _cmd_bench(args):
    from . import bench, parallel, peer, study

    methods = [m for m in args.methods.split(",") if m] if args.methods != "all" else list(bench.METHODS)
    sizes = study._int_list(args.sizes, "--sizes")
    cores = parallel.available()
    threads = study._int_list(args.threads, "--threads") if args.threads else sorted({1, cores})
    if args.repeat < 1:
        raise InputError(f"--repeat {args.repeat}: expected a whole number >= 1")
    rows, paired, threads_paired, probes = bench.main(methods, sizes, steps=args.steps, warmup=args.warmup,
                                                      json_path=args.json, progress=not args.quiet, threads=threads,
                                                      repeat=args.repeat)
    m = bench.machine()
    print(f"{m['processor']}, {m['cpus']} CPUs, Python {m['python']}")
    print(bench.format_table(rows))
    print("\nstages (own wall time per step):\n" + bench.format_stages(rows))
    scaling = bench.format_scaling(rows, threads_paired)
    if scaling:
        print("\nthreads (wall time per step, speed-up over one thread):\n" + scaling)
        print(bench.format_memory(probes["memory"]))
        print(bench.format_arithmetic(probes["arithmetic"]))
        print(bench.format_handoff(probes["handoff"]))
        print(bench.format_cores_alone(probes["cores_alone"]))
    ratio = peer.format_ratio(rows, paired)
    if ratio:
        print("\nours / peer (CPU time per cell and step, one core):\n" + ratio)
    return 0


def _out_dir(args, default, check=True):
    """``--out`` if given (refused if not empty, unless --force), else the first free one of
    ``default``, ``default-2``, ``default-3``, ... (`outdir.numbered`: --force replaces nothing)."""
    from pathlib import Path

    from .outdir import numbered

    if args.out is None:
        return numbered(default)
    out = Path(args.out)
    if check and out.exists() and any(out.iterdir()) and not args.force:
        raise InputError(f"--out {out}: directory exists and is not empty (use --force to replace it)")
    return out


def _cmd_cfl_limit(args):
    from . import stability_study as ss

    out = _out_dir(args, f"runs/cfl_limit_{_stem(args.scene)}")
    done = ss.study(args.scene, [m.strip() for m in args.methods.split(",") if m.strip()],
                    [x.strip() for x in args.limiters.split(",") if x.strip()], args.set, args.workers,
                    hi=args.hi, tol=args.tol, progress=not args.quiet)
    table = ss.format_table(done)
    print(table)
    out.mkdir(parents=True, exist_ok=True)
    ss.write_csv(out / "trials.csv", done)
    (out / "cfl_limit.md").write_text(table + "\n")
    print(f"-> {out}/cfl_limit.md, trials.csv")
    return 0


def _cmd_compare_figures(args):
    from . import figures

    out = _out_dir(args, f"runs/compare_{_stem(args.scene)}")
    snaps, files, wall = figures.main_compare(args.scene, [g for g in args.groups.split(",") if g], args.set,
                                              args.workers, out, args.dgmpm_cfl, progress=not args.quiet)
    for s in snaps:
        print(f"{s.method:<18} t = {s.time:.4g} s: {s.status}, {s.steps} steps, {s.wall_s:.1f} s"
              + (f" ({s.message})" if s.message else ""))
    for row in figures.agreement(snaps):
        print(f"t = {row['t']:.4g} s {row['field']:>8}: spread {row['spread']:.3f} of max |median| "
              f"(farthest: {row['farthest']})")
    print(f"-> {out}: {', '.join(files)} ({wall:.0f} s)")
    return 0


def _output_options(p, default):
    """--out, --force and --quiet of the commands that write an output folder."""
    p.add_argument("--out", default=None,
                   help=f"output directory (default {default}, or {default}-2, -3, ...: the first that is free)")
    p.add_argument("--force", action="store_true", help="replace the contents of an existing --out directory")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar (a run still says, in one line, when it compiles its kernels)")


def _quiet_stdout():
    """Point stdout at /dev/null, so that the interpreter's last flush of a closed pipe is silent."""
    import os
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):                # no file descriptor (stdout replaced in Python)
        pass


def main(argv=None):
    parser = argparse.ArgumentParser(prog="skdgmpm", description="DGMPM solver for impacts on solids")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="run a scene")
    p.add_argument("case", nargs="?", default=None,
                   help="scene name from cases/ (see 'skdgmpm list') or path to a .toml")
    p.add_argument("--threads", type=int, default=None,
                   help="threads of the compiled passes (default: run.threads, $SKDGMPM_THREADS or every core; "
                        "the answers are the same for any count)")
    p.add_argument("--resume", default=None, metavar="DIR",
                   help="continue the run checkpointed in DIR (stopped by SIGINT/SIGTERM, or killed)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key, e.g. --set method.cfl=0.5 (repeatable)")
    _output_options(p, "runs/CASE")
    p.set_defaults(func=_cmd_run)

    for command, help_text, default_methods in (
            ("converge", "convergence study against a scene's exact solution", "dgmpm,rk-dgfem"),
            ("compare", "speed against error: work-precision diagram of methods and orders",
             "dgmpm,rk-dgfem,ader-dgfem,ader-dgmpm")):
        p = sub.add_parser(command, help=help_text)
        p.add_argument("scene", help="scene with an exact solution, e.g. standing_wave_2d")
        p.add_argument("--methods", default=default_methods,
                       help="comma-separated: dgmpm, rk-dgfem, ader-dgfem, ader-dgmpm, mpm; method/integrator "
                            "picks a time integrator (rk-dgfem/rk2), mpm/UPDATE-SHAPE an MPM variant (mpm/cd-cpgimp)")
        p.add_argument("--orders", default="1,2,3", help="orders P of the high-order methods")
        p.add_argument("--cells", default="4,8,16", help="cells per direction")
        p.add_argument("--cfls", default=None,
                       help="CFL numbers (default: the scene's); one grid and several CFLs is a temporal study")
        p.add_argument("--measure", default="l2", choices=("l2", "wg08"),
                       help="l2: relative L2 error of each field at the end; wg08: max displacement error "
                            "over all particles and steps (needs a manufactured solution)")
        p.add_argument("--fields", default=None, help="fields to report (default: all of the exact solution)")
        if command == "compare":
            p.add_argument("--field", default=None, help="field of the diagram (default: the first reported)")
        p.add_argument("--reference", default=None, metavar="METHOD:P:CELLS",
                       help="fine DGFEM run to compare with when the scene has no exact solution, "
                            "e.g. rk-dgfem/rk4:3:40")
        p.add_argument("--workers", type=int, default=None,
                       help="local processes running the study (default: all cores; 1 runs here, "
                            "one run at a time: cleanest wall times)")
        p.add_argument("--dask", default=None, metavar="tcp://HOST:PORT",
                       help="run the study on this Dask distributed scheduler instead")
        p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene key")
        _output_options(p, f"runs/{command}_SCENE")
        p.set_defaults(func=_cmd_converge if command == "converge" else _cmd_compare)

    p = sub.add_parser("bench", help="benchmark every method on a 2D neo-Hookean impact (set-up, "
                                     "time per step/cell/dof, memory)")
    p.add_argument("--methods", default="dgmpm-ctu,dgmpm-dcu,ader-dgmpm-1,ader-dgfem-1,rk-dgfem-1",
                   help="comma-separated benchmark names, or 'all' (see skdgmpm.bench.METHODS); the peer "
                        "Clawpack/PyClaw rows are named apart: pyclaw-ctu, pyclaw-ctu-2 (skdgmpm.peer)")
    p.add_argument("--sizes", default="64,128", help="cells per side")
    p.add_argument("--steps", type=int, default=5, help="timed steps (median)")
    p.add_argument("--warmup", type=int, default=2, help="untimed steps first")
    p.add_argument("--json", default=None, help="also write the rows and the machine to this JSON file")
    p.add_argument("--threads", default=None,
                   help="thread counts to measure, e.g. 1,2 (default: 1 and every core: the scaling)")
    p.add_argument("--repeat", type=int, default=1,
                   help="measure the paired thread scaling this many times, the methods in turn (each "
                        "repeat and the lowest speed-up printed)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_bench)

    p = sub.add_parser("cfl-limit", help="largest stable CFL per method and limiter (bisection, in parallel)")
    p.add_argument("scene", help="scene name or path, e.g. lasat_2d")
    p.add_argument("--methods", default="dgmpm,rk-dgfem/rk2 S1,ader-dgfem S1T1,ader-dgmpm S1T1",
                   help="comma-separated labels of skdgmpm.stability_study.VARIANTS")
    p.add_argument("--limiters", default="none,barth-jespersen",
                   help="none, barth-jespersen, venkatakrishnan, barth-jespersen-invariant, ...")
    p.add_argument("--hi", type=float, default=2.0, help="largest CFL tried (2: the most a scene accepts)")
    p.add_argument("--tol", type=float, default=0.05, help="bisection stops when the bracket is this narrow")
    p.add_argument("--workers", type=int, default=None, help="parallel processes (default: all cores; 1: serial)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scene key, e.g. a coarse mesh: --set 'grid.mesh=\"lasat_12.msh\"'")
    _output_options(p, "runs/cfl_limit_SCENE")
    p.set_defaults(func=_cmd_cfl_limit)

    p = sub.add_parser("compare-figures", help="sigma11 maps and bottom-line plots of several methods (PNG, CSV)")
    p.add_argument("scene", help="scene name or path, e.g. multiholed_cell_2d")
    p.add_argument("--groups", default="S1,S2,dgmpm", help="S1 (S1T1 methods), S2 (S2T2), dgmpm, mpm (CD-cpGIMP)")
    p.add_argument("--dgmpm-cfl", type=float, default=0.5, help="CFL of first-order DGMPM (CTU, 1 ppc)")
    p.add_argument("--workers", type=int, default=None, help="parallel processes (default: all cores; 1: serial)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scene key")
    _output_options(p, "runs/compare_SCENE")
    p.set_defaults(func=_cmd_compare_figures)

    p = sub.add_parser("list", help="list the scenes")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("scenes", help="show or copy a shipped scene, or print every scene key")
    actions = p.add_subparsers(dest="action", required=True)
    q = actions.add_parser("show", help="print a scene file (a name from 'skdgmpm list', or a path)")
    q.add_argument("name")
    q = actions.add_parser("copy", help="copy a scene with its mesh file into DIR, to start a scene of your own")
    q.add_argument("name")
    q.add_argument("dir")
    q.add_argument("--force", action="store_true", help="overwrite files that exist in DIR")
    q = actions.add_parser("schema", help="every scene key: type, unit, default, example, methods (docs/scenes.md)")
    q.add_argument("--markdown", action="store_true", help="the Markdown of docs/scenes.md")
    p.set_defaults(func=_cmd_scenes)

    p = sub.add_parser("cache", help="list the compiled kernels' folders on disk (one per source version)")
    p.add_argument("--prune", action="store_true",
                   help="remove every folder but the one of these sources (others compile again when used)")
    p.set_defaults(func=_cmd_cache)

    p = sub.add_parser("stability", help="von Neumann analysis of a particle layout: 1D (R18 §6) or the 2D step")
    p.add_argument("--layout", help="1D: parent coordinates in a cell, e.g. 0.25,0.75")
    p.add_argument("--dim", type=int, choices=(1, 2), default=1,
                   help="2: the 2D step's limits (default 1: R18's analysis for dgmpm, the 1D step otherwise)")
    p.add_argument("--per-cell", type=int, default=1, help="2D: particles a direction in a cell (default 1)")
    p.add_argument("--nu", type=float, default=0.3, help="2D: Poisson's ratio (default 0.3)")
    p.add_argument("--method", default="dgmpm", choices=("dgmpm", "ader-dgmpm", "ader-dgfem", "rk-dgfem"),
                   help="the method whose step is analysed (default dgmpm: Euler / RK2 x CTU / DCU in 2D); "
                        "other than dgmpm, in 1D too")
    p.add_argument("--order", type=int, default=1, help="order P of ADER and RK-DGFEM (default 1)")
    p.add_argument("--integrator", choices=("rk2", "rk4"), help="RK-DGFEM's (default rk2 for P = 1, else rk4)")
    p.add_argument("--json", action="store_true", help="also print the report as JSON")
    p.set_defaults(func=_cmd_stability)

    args = parser.parse_args(argv)
    formatwarning = warnings.formatwarning
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.formatwarning = lambda msg, cat, *a, **k: f"warning: {msg}\n"
        try:
            return args.func(args)
        except InputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_INPUT
        except OutputError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_OUTPUT
        except BrokenPipeError:             # `skdgmpm list | head -1`: the reader is gone, stop quietly
            _quiet_stdout()
            return EXIT_BROKEN_PIPE
        except KeyboardInterrupt:
            print("error: interrupted (before the first step, or a second Ctrl-C: no new checkpoint)",
                  file=sys.stderr)
            return 130
        finally:
            warnings.formatwarning = formatwarning      # main() may be called from Python


if __name__ == "__main__":
    sys.exit(main())
