"""Command line: ``python -m mpdem run|restart|stiffen|analyze|collect|sweep|info|export|bench``.

    python -m mpdem run [CONFIG.toml] [--set section.key=value ...] [--out DIR] [--walltime HH:MM:SS] [--threads T]
    python -m mpdem restart RUN_DIR|STATE_FILE [--set ...] [--walltime HH:MM:SS] [--threads T]
    python -m mpdem stiffen RUN_DIR --k_n K [--out DIR] [--set ...] [--walltime HH:MM:SS] [--threads T]
    python -m mpdem analyze RUN_DIR|STATE_FILE [--out DIR] [--set analysis.key=value ...] [--series]
    python -m mpdem collect RUN_DIR ... [--out DIR]
    python -m mpdem sweep TABLE ... --out DIR [--config FILE] [--jobs J] [--ranks R] [--threads T] [--set ...]
    python -m mpdem info FILE [--digest]
    python -m mpdem export FILE --format FORMAT          (python -m mpdem export -h lists them)
        [--out PATH]
    python -m mpdem bench --table FILE [--steps S] [--threads T] [--tile NXxNY] [--set ...]
    python -m mpdem bench --io|--analysis [--N 1000000]

Exit status: 0 finished (converged), 3 finished at run.max_steps without
converging, 75 stopped early by --walltime, SIGTERM, SIGUSR1 or SIGINT after
writing a checkpoint ("not finished, restart me"; a second SIGINT stops at once,
without it: 1), 1 error, 2 usage error, 128 + the
signal (143 SIGTERM, 130 SIGINT) stopped before the first step, nothing saved
(``watch``).

MPI starts here (``parallel.world``) and its Channel is passed down; an
exception on any rank aborts all ranks with its message.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import tomllib

from .errors import EXIT_ERROR, EXIT_OK, EXIT_RESTART

T_START = time.monotonic()
# stop signals received before the run loop takes over (a job may end during set-up)
SIGNALS = []


def walltime(text):
    """Seconds of ``[D-]HH:MM:SS``, ``MM:SS`` or plain seconds (argparse type)."""
    import math
    try:
        days, dash, rest = text.partition("-") if "-" in text else ("0", "", text)
        parts = [float(p) for p in [days] + rest.split(":")]
        if (dash and not days) or not 2 <= len(parts) <= 4 or any(not math.isfinite(p) or p < 0 for p in parts):
            raise ValueError
        sec = sum(p * 60 ** k for k, p in enumerate(reversed(parts[1:]))) + 86400 * parts[0]
        if sec <= 0:
            raise ValueError
        return sec
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--walltime {text!r}: accepted [D-]HH:MM:SS, MM:SS or seconds, greater than 0") from None


def positive_int(flag):
    """argparse type: an integer >= 1, refused with a message naming ``flag``."""
    def parse(text):
        try:
            n = int(text)
            if n >= 1:
                return n
        except ValueError:
            pass
        raise argparse.ArgumentTypeError(f"{flag} {text!r}: accepted an integer >= 1")
    return parse


def tile(text):
    """``NXxNY`` -> (NX, NY), both >= 1 (argparse type of --tile)."""
    try:
        nx, ny = (int(t) for t in text.lower().split("x"))
        if nx >= 1 and ny >= 1:
            return nx, ny
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"--tile {text!r}: accepted NXxNY with integers NX, NY >= 1 (e.g. 2x2)")


def seconds(flag):
    """argparse type: seconds >= 0, refused with a message naming ``flag``."""
    def parse(text):
        try:
            sec = float(text)
            if sec >= 0 and sec != float("inf"):
                return sec
        except ValueError:
            pass
        raise argparse.ArgumentTypeError(f"{flag} {text!r}: accepted seconds >= 0")
    return parse


def device_items(args):
    """``--device D`` as the --set item it stands for (engine.device=D); none without it."""
    return [f"engine.device={args.device}"] if getattr(args, "device", None) else []


def default_out():
    return os.path.join("runs", time.strftime("run-%Y%m%d-%H%M%S"))


def cmd_run(args, net):
    from . import api, config
    from .errors import AgreedError, InputError
    try:
        cfg = config.load_run_config(args.config, args.set + device_items(args))
    except (config.ConfigError, InputError) as e:   # the same inputs on every rank: the same error
        raise AgreedError(str(e)) from None
    r = api.run(cfg, args.out or default_out(), threads=None, force=args.force, quiet=args.quiet,
                walltime=args.walltime, walltime_margin=args.walltime_margin, net=net, t_start=T_START,
                signals=SIGNALS)
    return r.exit_status


def cmd_stiffen(args, net):
    from . import api, config, stiffen
    from .errors import AgreedError, InputError
    try:
        cfg = stiffen.rung_config(args.run, args.k_n, args.set + device_items(args))
    except (config.ConfigError, InputError, OSError) as e:
        raise AgreedError(str(e)) from None
    out = args.out or f"{os.path.normpath(args.run)}-kn{args.k_n:g}"
    r = api.run(cfg, out, threads=None, force=args.force, quiet=args.quiet, walltime=args.walltime,
                walltime_margin=args.walltime_margin, net=net, t_start=T_START, signals=SIGNALS)
    return r.exit_status


def cmd_restart(args, net):
    from . import api
    r = api.restart(args.target, threads=None, quiet=args.quiet, walltime=args.walltime,
                    walltime_margin=args.walltime_margin, net=net, t_start=T_START, signals=SIGNALS,
                    set_items=args.set + device_items(args))
    return r.exit_status


def cmd_export(args, net):
    from .io import export
    if net.rank == 0:          # one writer, however it was launched
        out, notes = export.export(args.file, args.format, args.out)
        print(f"wrote {out}")
        for line in notes:
            print(line)
    return EXIT_OK


def cmd_info(args, net):
    from .io import checkpoint
    if net.rank != 0:
        return EXIT_OK
    arrays, attrs = checkpoint.read_state(args.file, pairs=True)
    if args.digest:
        print(checkpoint.digest(arrays))
        return EXIT_OK
    n = len(arrays["id"])
    print(f"{args.file}: {attrs.get('format')} version {attrs.get('version')}, kind {attrs.get('kind')}, "
          f"written by {attrs.get('ranks', '?')} rank(s), checksums verified")
    print(f"  step {attrs.get('step')}, time {attrs.get('time')}, {n} particles "
          f"({attrs.get('n_mobile')} mobile, {attrs.get('n_bed')} bed), "
          f"{len(arrays['partner'])} contact slots, box {attrs.get('L_x')} x {attrs.get('L_y')}"
          + (", converged" if attrs.get("converged") else ""))
    if "id_i" in arrays:
        print(f"  contact list: {len(arrays['id_i'])} contacts (F_n, F_t, Delta s)")
    try:
        c = tomllib.loads(attrs.get("config", ""))
        ct = c.get("contact", {})
        print(f"  contact {ct.get('model')} k_n {ct.get('k_n')} mu {ct.get('mu')} "
              f"epsilon {ct.get('epsilon')} dt {c.get('integration', {}).get('dt')}, "
              f"N {c.get('pour', {}).get('N')} phi_i {c.get('pour', {}).get('phi_i')} "
              f"seed {c.get('run', {}).get('seed')} max_steps {c.get('run', {}).get('max_steps')}")
    except tomllib.TOMLDecodeError:
        pass
    return EXIT_OK


def cmd_analyze(args, net):
    from .analysis.report import analyze
    if net.rank != 0:
        return EXIT_OK
    if net.size > 1:
        print(f"analyze: one process does the work (numba threads); {net.size - 1} rank(s) idle")
    if args.series:
        from .analysis.series import series
        series(args.target, args.set, args.out, plots=not args.no_plots, log=_quiet(args.quiet))
        return EXIT_OK
    analyze(args.target, args.out, args.set, plots=not args.no_plots, log=_quiet(args.quiet),
            keep_packing=args.packing)
    return EXIT_OK


def cmd_collect(args, net):
    from .campaign.collect import collect
    if net.rank != 0:
        return EXIT_OK
    collect(args.runs, args.out, analyze_missing=not args.no_analyze, log=_quiet(args.quiet),
            figure_format=args.figure_format)
    return EXIT_OK


def cmd_sweep(args):
    """Run the rows of sweep tables here, J at a time, then collect them (no MPI in this process)."""
    from .campaign import sweep
    from .config import ConfigError
    try:
        rows = sweep.plan(args.tables, args.config, args.set, out=args.out)
    except ConfigError as e:
        sys.stderr.write(f"mpdem: error: {e}\n")
        return EXIT_ERROR
    jobs = args.jobs or sweep.default_jobs(args.ranks, args.threads)
    rc = sweep.Sweep(rows, args.out, args.config, args.set, jobs=jobs, ranks=args.ranks, threads=args.threads,
                     progress=args.progress).run()
    if rc == EXIT_RESTART or args.no_collect:
        return rc
    from .campaign.collect import collect
    from .analysis.report import AnalysisError
    try:
        collect([args.out], args.collect or os.path.join(args.out, "collect"))
    except AnalysisError as e:
        sys.stderr.write(f"mpdem: error: {e}\n")   # the message starts "collect: "
        return EXIT_ERROR
    return rc


def _quiet(quiet):
    return (lambda msg: None) if quiet else print


def cmd_bench(args, net):
    from .bench import run_analysis_bench, run_io_bench, run_table_bench
    (run_io_bench if args.io else run_analysis_bench if args.analysis else run_table_bench)(args, net)
    return EXIT_OK


def check_bench_mode(p, args):
    """Exactly one bench mode: --table FILE (the default bench), --io or --analysis (usage error otherwise)."""
    modes = [flag for flag, on in (("--table", args.table is not None), ("--io", args.io),
                                   ("--analysis", args.analysis)) if on]
    if not modes:
        p.error("bench needs --table FILE: a particle table (id x y z [vx vy vz] [fixed], plain or gzip), "
                "e.g. --table path/to/landed20k.txt.gz; or --io or --analysis")
    if len(modes) > 1:
        p.error(f"bench: choose one of {', '.join(modes)}")


def threads_wanted(args):
    """numba threads the command asks for: --threads, else 1 for run, restart and the table
    bench; None (numba's default) for the other commands and bench --io/--analysis."""
    n = getattr(args, "threads", None)
    if n is None and (args.cmd in ("run", "restart", "stiffen") or (args.cmd == "bench" and args.table is not None)):
        n = 1
    return n


def parser():
    from ._version import __version__
    p = argparse.ArgumentParser(prog="mpdem", description="Discrete-element sphere packings (docs/model.md).")
    p.add_argument("--version", action="version", version=f"mpdem {__version__}")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a pile (the built-in example without CONFIG)")
    r.add_argument("config", nargs="?", help="TOML config in reduced units")
    r.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a config value (repeatable)")
    r.add_argument("--out", help="run directory (default runs/run-DATE-TIME)")
    r.add_argument("--force", action="store_true", help="reuse an --out that holds a run")
    r.add_argument("--quiet", action="store_true", help="progress to the log file only")
    rs = sub.add_parser("restart", help="continue a run from its newest valid checkpoint or a state file")
    rs.add_argument("target", metavar="RUN_DIR|STATE_FILE")
    rs.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="change run.max_steps, stop.*, checks.*, decomp.*, engine.*, output.* or analysis.*; "
                         "flow.time while the flow runs (docs/model.md 5.5)")
    rs.add_argument("--quiet", action="store_true", help="progress to the log file only")
    sf = sub.add_parser("stiffen", help="a new run: a finished run's pile stiffened to --k_n through the ramp "
                                        "(docs/model.md 6.6), then settled by the stop rule")
    sf.add_argument("run", metavar="RUN_DIR", help="a finished run (its config.toml and final.h5)")
    sf.add_argument("--k_n", type=float, required=True, metavar="K",
                    help="the new contact.k_n [m g / d], at most ten times the run's")
    sf.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="override a value of the new run's config (run.max_steps, stiffen.ramp_time, ...)")
    sf.add_argument("--out", help="run directory (default RUN_DIR-knK)")
    sf.add_argument("--force", action="store_true", help="reuse an --out that holds a run")
    sf.add_argument("--quiet", action="store_true", help="progress to the log file only")
    for q in (r, rs, sf):
        q.add_argument("--device", choices=("cpu", "gpu"), default=None,
                       help="what steps the particles (engine.device; default the config's, cpu)")
        q.add_argument("--threads", type=positive_int("--threads"), default=1, metavar="T",
                       help="numba threads per rank (default 1)")
        q.add_argument("--bind", choices=("auto", "none"), default="auto",
                       help="auto (default): where the launcher left this node's ranks unbound and they fit its "
                            "cores, each rank binds itself to --threads cores of its own; none: as launched (two "
                            "launches side by side on one node: docs/cluster.md)")
        q.add_argument("--walltime", type=walltime, metavar="HH:MM:SS",
                       help="write a checkpoint and exit (status 75) before this much wall time")
        q.add_argument("--walltime-margin", type=seconds("--walltime-margin"), default=None, metavar="SECONDS",
                       help="seconds kept free before --walltime besides twice the last checkpoint "
                            "write time (default min(60, walltime / 20))")
    e = sub.add_parser("export", help="write a state file for other tools (OVITO, LAMMPS, ASE)")
    e.add_argument("file")
    from .io.export import FORMATS
    e.add_argument("--format", required=True, choices=tuple(FORMATS), metavar="FORMAT",
                   help="; ".join(f"{f.name}: {f.about}" for f in FORMATS.values()))
    e.add_argument("--out", help="output path (default: beside FILE, as each format says)")
    b = sub.add_parser("bench", help="benchmark: ns per atom-step from a particle table (--table), "
                                      "or checkpoint IO (--io), or analysis (--analysis)")
    b.add_argument("--table", metavar="FILE",
                   help="particle table to time (id x y z [vx vy vz] [fixed], plain or gzip; or an mpdem state "
                        "or packing file, or a LAMMPS data file or dump with --set run.fixed_types=[T], in its "
                        "own box), e.g. path/to/landed20k.txt.gz; run with the settings of the LAMMPS "
                        "comparison: Hooke, k_n 2e5, epsilon 0.88, gamma_t = gamma_n/2, mu 0.5, dt 1e-4, skin 0.2")
    b.add_argument("--steps", type=positive_int("--steps"), default=2000, help="timed steps (default 2000)")
    b.add_argument("--threads", type=positive_int("--threads"), default=None, metavar="T",
                   help="numba threads per rank (default 1 with --table; numba's default otherwise)")
    b.add_argument("--bind", choices=("auto", "none"), default="auto",
                   help="auto (default): where the launcher left this node's ranks unbound and they fit its "
                        "cores, each rank binds itself to --threads cores of its own; none: as launched (two "
                        "launches side by side on one node: docs/cluster.md)")
    b.add_argument("--device", choices=("cpu", "gpu"), default="cpu",
                   help="time the CPU engine (default) or the GPU engine (--table only)")
    b.add_argument("--tile", type=tile, default=(1, 1), metavar="NXxNY",
                   help="time NX x NY copies of the table side by side in x and y (e.g. 2x2)")
    b.add_argument("--N", type=int, default=20000, help="spheres of --io and --analysis (default 20000)")
    b.add_argument("--mu", type=float, default=0.5, help="friction of the --analysis pile (default 0.5)")
    b.add_argument("--cache", default=None, help="directory for the landed pile (default ~/.cache/mpdem/bench)")
    b.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a value of the --table bench (e.g. box.L_x=10 integration.skin=0.3)")
    b.add_argument("--io", action="store_true",
                   help="time a checkpoint write and read of N synthetic particles instead "
                        "(the file goes to --cache, default the system temp directory)")
    b.add_argument("--analysis", action="store_true",
                   help="time `mpdem analyze` of an N-sphere snapshot (copies of the landed pile side by "
                        "side, written by all ranks); use with --N 1000000")
    b.add_argument("--repeat", type=int, default=3, help="repetitions of the IO and analysis benchmarks (default 3)")
    an = sub.add_parser("analyze", help="measure a packing: z, phi, g(r), alpha, P(zeta) (docs/model.md 6)")
    an.add_argument("target", metavar="RUN_DIR|STATE_FILE",
                    help="a finished run (its final.h5) or a snapshot, checkpoint or final state")
    an.add_argument("--out", help="output directory (default RUN/analysis, or RUN/analysis/snap-NNNNN)")
    an.add_argument("--set", action="append", default=[], metavar="analysis.KEY=VALUE",
                    help="change an analysis setting (repeatable)")
    an.add_argument("--no-plots", action="store_true", help="summary and tables only")
    an.add_argument("--packing", action="store_true",
                    help="also keep RUN/packing.npz beside a final.h5: its positions and contact forces, "
                         "compressed, which analyze can read when final.h5 is gone")
    an.add_argument("--series", action="store_true",
                    help="measure every snapshot of RUN_DIR (bulk z, phi, contacts, E_k) into "
                         "RUN/analysis/series.csv and series.png: how the run settled")
    an.add_argument("--quiet", action="store_true", help="print nothing")
    co = sub.add_parser("collect", help="many runs -> the paper's tables and figures (Figs. 2-9)")
    co.add_argument("runs", nargs="+", metavar="RUN_DIR", help="run directories (or directories holding them)")
    co.add_argument("--out", default="paper", help="output directory (default ./paper)")
    co.add_argument("--no-analyze", action="store_true",
                    help="use only runs that already have analysis/summary.json, as they are (without it a run "
                         "is analysed when it has none, or when it is of another step of the run's state or of "
                         "older measures than this mpdem's)")
    co.add_argument("--quiet", action="store_true", help="print nothing")
    co.add_argument("--figure-format", default="png", metavar="FMT[,FMT]",
                    help="figure formats: png (default), pdf, svg, several joined by commas")
    sw = sub.add_parser("sweep", help="run the rows of sweep tables on this machine, then collect them")
    sw.add_argument("tables", nargs="+", metavar="TABLE",
                    help="sweep tables (columns mu epsilon k_n phi_i seed or section.key, one run per line)")
    sw.add_argument("--out", required=True, help="directory of the run directories (one per row, named from it)")
    sw.add_argument("--config", help="TOML config under each row's values (default: the built-in example)")
    sw.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="a value for every row, under the row's own (repeatable)")
    sw.add_argument("--jobs", type=positive_int("--jobs"), default=None, metavar="J",
                    help="rows at a time (default cores / (R T))")
    sw.add_argument("--ranks", type=positive_int("--ranks"), default=1, metavar="R",
                    help="MPI ranks per row (default 1)")
    sw.add_argument("--threads", type=positive_int("--threads"), default=1, metavar="T",
                    help="numba threads per rank (default 1)")
    sw.add_argument("--progress", type=seconds("--progress"), default=300.0, metavar="SECONDS",
                    help="seconds between progress lines (default 300)")
    sw.add_argument("--collect", metavar="DIR", help="where collect writes (default OUT/collect)")
    sw.add_argument("--no-collect", action="store_true", help="run the rows only")
    i = sub.add_parser("info", help="what a state file holds")
    i.add_argument("file")
    i.add_argument("--digest", action="store_true", help="print a SHA-256 of the state sorted by id")
    return p


def main(argv=None, program=False):
    """The command line; ``program``: this process is ``python -m mpdem`` and ends after it."""
    import signal
    if program:
        from . import watch
        watch.ENDS_PROCESS = True      # a set-up's stop may end the process itself (``watch``)
    old = {s: signal.signal(s, lambda signum, frame: SIGNALS.append(int(signum)))
           for s in (signal.SIGTERM, signal.SIGUSR1)}
    # an in-process caller (tests) gets its thread settings back
    from . import threads
    old_threads = threads.snapshot() if "numba" in sys.modules else None
    try:
        return _main(argv)
    finally:
        for s, h in old.items():
            # the program's work is done: a stop signal while the process shuts down (MPI
            # finalize; a batch system's early warning) must not turn its exit status into a
            # death by signal
            signal.signal(s, signal.SIG_IGN if program else h)
        if old_threads is not None:
            threads.restore(old_threads)


def threads_warnings(n, cores):
    """Warnings for ``--threads n`` in a process that may use ``cores`` cores."""
    out = []
    if n > cores:
        out.append(f"--threads {n}, but this process may run on {cores} core(s), so its threads share them "
                   f"(under Open MPI's mpiexec: --bind-to none, or --map-by slot:PE={n})")
    from .threads import PASSIVE, oversubscribed, ranks_on_node
    local, node = ranks_on_node(), os.cpu_count() or 1
    if local * n > node:
        out.append(f"{local} rank(s) x {n} threads on this node's {node} cores")
    if oversubscribed(n, cores):
        policy = ", ".join(f"{k}={os.environ.get(k, v)}" for k, v in PASSIVE.items())
        out.append(f"threads outnumber cores, so waiting threads sleep ({policy}): slower than fewer threads "
                   f"in proportion; expect little or no gain over --threads 1")
    return out


def _main(argv):
    p = parser()
    args = p.parse_args(argv)
    if args.cmd == "bench":
        check_bench_mode(p, args)
    if args.cmd == "sweep":         # a manager of mpdem processes: no MPI, no kernels here
        return cmd_sweep(args)
    from .parallel import world
    net = world(EXIT_ERROR)
    # before anything imports the numba kernels (numba sizes its pool at import)
    from .threads import ThreadsError, bind, configure, usable_cores
    n_threads = threads_wanted(args)
    if n_threads is not None and getattr(args, "bind", "none") == "auto":
        # before numba starts its threads, which take the affinity of the thread that starts them
        bind(net.comm, n_threads)
    try:
        if n_threads is not None:
            configure(n_threads)
    except ThreadsError as e:
        _fail(net, f"mpdem: error: {e}")
    if n_threads and net.rank == 0:
        for w in threads_warnings(n_threads, usable_cores()):
            sys.stderr.write(f"mpdem: warning: {w}\n")
    from .errors import Interrupted, MpdemError
    handlers = {"run": cmd_run, "restart": cmd_restart, "stiffen": cmd_stiffen, "info": cmd_info, "export": cmd_export,
                "bench": cmd_bench, "analyze": cmd_analyze, "collect": cmd_collect}
    try:
        return handlers[args.cmd](args, net)
    except MpdemError as e:
        # a stop signal before the first step (``watch``): its own status, not an error
        stopped = isinstance(e, Interrupted)
        if e.agreed:               # every rank is here with the same message: one line, no abort
            if net.rank == 0:
                sys.stderr.write(f"mpdem: {'' if stopped else 'error: '}{e}\n")
                sys.stderr.flush()
            _exit(net, e.status if stopped else EXIT_ERROR)
        _fail(net, f"mpdem: error: {e}")
    except NotImplementedError as e:
        _fail(net, f"mpdem: error: {e}")
    except BrokenPipeError:
        # the reader of the output went away (`mpdem info FILE | head`): stop quietly, as text tools do
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except OSError as e:           # a file this rank could not write or read (a full disk, a quota, permissions)
        where = f"{e.filename}: " if e.filename else ""
        ranks = f" (rank {net.rank}; ending every rank)" if net.parallel else ""
        _fail(net, f"mpdem: error: {where}{e.strerror or e}{ranks}")
    except KeyboardInterrupt:
        _fail(net, "mpdem: interrupted")
    except Exception:
        import traceback
        _fail(net, "mpdem: internal error on rank %d:\n%s" % (net.rank, traceback.format_exc()))


def _exit(net, status):
    """Exit with ``status``; past the HDF5 library's clean-up (which MPI_Finalize runs too) where it
    holds a handle it would crash on (``checkpoint.held``)."""
    ckpt = sys.modules.get("mpdem.io.checkpoint")
    if ckpt is None or not ckpt.held():
        sys.exit(status)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def _fail(net, msg):
    sys.stderr.write(msg.rstrip() + "\n")
    sys.stderr.flush()
    net.abort(EXIT_ERROR)
    sys.exit(EXIT_ERROR)


if __name__ == "__main__":
    sys.exit(main(program=True))
