"""Command line: ``python -m mpdem run|bench|info``.

    python -m mpdem run [CONFIG.toml] [--set section.key=value ...] [--out DIR]
    python -m mpdem bench [--steps N] [--set ...]
    python -m mpdem info FILE [--digest]

MPI starts here and the communicator is passed down; an exception on any
rank aborts all ranks with its message.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import tomllib
from importlib import resources

EXIT_OK, EXIT_ERROR, EXIT_USAGE = 0, 1, 2


def start_mpi():
    """COMM_WORLD, after checking the launcher and mpi4py agree."""
    from mpi4py import MPI
    comm = MPI.COMM_WORLD
    launched = os.environ.get("OMPI_COMM_WORLD_SIZE") or os.environ.get("PMI_SIZE")
    if launched and int(launched) > 1 and comm.Get_size() == 1:
        # each process is a world of its own: Abort would stop only itself
        sys.stderr.write(
            f"mpdem: started by an mpiexec of {launched} processes, but mpi4py sees a world of "
            f"size 1: mpi4py was built for a different MPI ({MPI.Get_library_version().strip(chr(0)).splitlines()[0]}).\n"
            f"       Use the mpiexec of the MPI that mpi4py was built with (the .venv/bin/mpiexec "
            f"wrapper), or rebuild mpi4py (tools/setup.sh).\n")
        sys.exit(EXIT_ERROR)
    return comm


def default_out():
    return os.path.join("runs", time.strftime("run-%Y%m%d-%H%M%S"))


def cmd_run(args, comm):
    from . import config
    from .simulation import Run
    if args.config is None:
        text = resources.files("mpdem").joinpath("example.toml").read_text()
        raw = config.flatten(tomllib.loads(text), origin="built-in example")
        cfg = config.load(None, args.set, base=raw)
    else:
        cfg = config.load(args.config, args.set)
    out = args.out or default_out()
    if os.path.exists(os.path.join(out, "config.toml")) and not args.force:
        raise config.ConfigError(f"--out {out}: already holds a run (config.toml); "
                                 f"choose another directory or pass --force")
    run = Run(cfg, out, comm, quiet=args.quiet)
    run.prepare()
    run.run()
    run.finish()
    return EXIT_OK if run.converged else 3


def cmd_info(args, comm):
    from . import checkpoint
    arrays, attrs = checkpoint.read_state(args.file)
    if args.digest:
        print(checkpoint.digest(arrays))
        return EXIT_OK
    n = len(arrays["id"])
    print(f"{args.file}: {attrs.get('format')} version {attrs.get('version')}, kind {attrs.get('kind')}")
    print(f"  step {attrs.get('step')}, time {attrs.get('time')}, {n} particles "
          f"({attrs.get('n_mobile')} mobile, {attrs.get('n_bed')} bed), "
          f"{len(arrays['partner'])} contact slots, box {attrs.get('L_x')} x {attrs.get('L_y')}")
    try:
        c = tomllib.loads(attrs.get("config", ""))
        ct = c.get("contact", {})
        print(f"  contact {ct.get('model')} k_n {ct.get('k_n')} mu {ct.get('mu')} "
              f"epsilon {ct.get('epsilon')} dt {c.get('integration', {}).get('dt')}")
    except tomllib.TOMLDecodeError:
        pass
    return EXIT_OK


def cmd_bench(args, comm):
    from .bench import run_bench
    run_bench(args, comm)
    return EXIT_OK


def parser():
    p = argparse.ArgumentParser(prog="mpdem", description="Discrete-element sphere packings (physics.md).")
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="run a pile (the built-in example without CONFIG)")
    r.add_argument("config", nargs="?", help="TOML config in reduced units")
    r.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a config value (repeatable)")
    r.add_argument("--out", help="run directory (default runs/run-DATE-TIME)")
    r.add_argument("--force", action="store_true", help="reuse an --out that holds a run")
    r.add_argument("--quiet", action="store_true", help="progress to the log file only")
    b = sub.add_parser("bench", help="benchmark: ns per particle-step on a landed pile")
    b.add_argument("--steps", type=int, default=2000, help="timed steps (default 2000)")
    b.add_argument("--N", type=int, default=20000, help="mobile spheres (default 20000)")
    b.add_argument("--mu", type=float, default=0.5)
    b.add_argument("--cache", default=None, help="directory for the landed pile (default ~/.cache/mpdem/bench)")
    b.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override a value of the timed part (e.g. integration.skin=0.3)")
    i = sub.add_parser("info", help="what a state file holds")
    i.add_argument("file")
    i.add_argument("--digest", action="store_true", help="print a SHA-256 of the state sorted by id")
    return p


def main(argv=None):
    args = parser().parse_args(argv)
    comm = start_mpi()
    from .build import InputError
    from .checkpoint import StateFileError
    from .config import ConfigError
    from .simulation import RunError
    handlers = {"run": cmd_run, "info": cmd_info, "bench": cmd_bench}
    try:
        return handlers[args.cmd](args, comm)
    except (ConfigError, InputError, StateFileError, RunError, NotImplementedError) as e:
        _fail(comm, f"mpdem: error: {e}")
    except KeyboardInterrupt:
        _fail(comm, "mpdem: interrupted")
    except Exception:
        import traceback
        _fail(comm, "mpdem: internal error on rank %d:\n%s" % (comm.Get_rank(), traceback.format_exc()))


def _fail(comm, msg):
    sys.stderr.write(msg.rstrip() + "\n")
    sys.stderr.flush()
    if comm.Get_size() > 1:
        comm.Abort(EXIT_ERROR)
    sys.exit(EXIT_ERROR)


if __name__ == "__main__":
    sys.exit(main())
