"""Sweep rows to a lent GPU machine and back (``tools/gpu_check.sh``'s ``PARTS=rows``).

A lent machine gets the checkout (without the committed checkpoints: ``tools/device_slim.sh``) and
what a call carries, and sends back at most eight files. This packs what its sweep needs to go on
where the rows stand here, and puts what came back where the rows live:

    python tools/device_rows.py pack RUNS TABLE [TABLE ...] [--config CFG] [--into .devdata/rows]
        each row of the tables (named as ``mpdem sweep`` names them) whose directory under RUNS
        holds a run: a finished row as its config.toml and analysis/summary.json (the sweep there
        skips it), an unfinished one as its files and its newest checkpoint (the sweep there
        restarts it); rows not begun travel as nothing and start afresh there
    python tools/device_rows.py unpack RUNS FILE.tgz [...]
        each row directory that came back (``gpu_check.sh`` packs each as ROW.tgz) into RUNS/ROW:
        its files over the ones here, but the config.toml here kept (the device's says
        engine.device = "gpu"); checkpoints older than the newest there deleted here (a finished
        row keeps none); prints the git commands that track what the project commits of a row

then ``ROWS_FROM=.devdata/rows`` (carried) on the device: docs/gpu.md, "Rows on a lent GPU".
"""
import argparse
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile

from mpdem.campaign.sweep import SUMMARY, finished, plan
from mpdem.io import rundir


def newest_checkpoint(run):
    """The path of the run's newest checkpoint, or None."""
    ck = rundir.checkpoints(run)
    return ck[-1][1] if ck else None


def pack(runs, tables, config_path, into):
    """Copy the rows' state under ``runs`` into ``into`` (emptied first); returns
    {row name: "finished" | "checkpoint"} for the rows packed."""
    shutil.rmtree(into, ignore_errors=True)
    os.makedirs(into)
    packed = {}
    for row in plan(tables, config_path, out=runs):
        src, dst = os.path.join(runs, row.name), os.path.join(into, row.name)
        if finished(src) and os.path.exists(os.path.join(src, SUMMARY)):
            os.makedirs(os.path.join(dst, "analysis"))
            shutil.copy2(os.path.join(src, "config.toml"), dst)
            shutil.copy2(os.path.join(src, SUMMARY), os.path.join(dst, SUMMARY))
            packed[row.name] = "finished"
            continue
        ck = newest_checkpoint(src)
        if ck is None:
            continue
        os.makedirs(os.path.join(dst, rundir.CKPT_DIR))
        for f in os.listdir(src):
            p = os.path.join(src, f)
            if os.path.isfile(p) and not f.startswith("."):     # not the run's .lock
                shutil.copy2(p, dst)
        shutil.copy2(ck, os.path.join(dst, rundir.CKPT_DIR))
        packed[row.name] = "checkpoint"
    return packed


def _tracked(path):
    """Whether git tracks ``path`` (False outside a checkout)."""
    r = subprocess.run(["git", "ls-files", "--error-unmatch", path], capture_output=True)
    return r.returncode == 0


def _results(run):
    """The files of a run directory that the project commits: a finished row's summaries, config,
    packing and analysis tables; an unfinished row's config and newest checkpoint."""
    if os.path.exists(os.path.join(run, "summary.json")):
        keep = ["config.toml", "summary.json", "packing.npz"]
        out = [os.path.join(run, f) for f in keep if os.path.exists(os.path.join(run, f))]
        adir = os.path.join(run, "analysis")
        if os.path.isdir(adir):
            out += sorted(os.path.join(adir, f) for f in os.listdir(adir) if f.endswith((".csv", ".json")))
        return out
    ck = newest_checkpoint(run)
    return [os.path.join(run, "config.toml")] + ([ck] if ck else [])


def unpack(runs, archives):
    """Each archive's row directory into ``runs``; returns (removed, to_commit) paths for git."""
    removed, to_commit = [], []
    for a in archives:
        with tempfile.TemporaryDirectory() as tmp:
            with tarfile.open(a) as tf:
                tf.extractall(tmp, filter="data")
            (name,) = os.listdir(tmp)
            src, dst = os.path.join(tmp, name), os.path.join(runs, name)
            os.makedirs(dst, exist_ok=True)
            keep_config = os.path.exists(os.path.join(dst, "config.toml"))
            theirs = newest_checkpoint(src)
            for old in [p for _, p in rundir.checkpoints(dst)]:
                if theirs is None or os.path.basename(old) != os.path.basename(theirs):
                    removed.append(old)
                    os.remove(old)
            for root, _, files in os.walk(src):
                rel = os.path.relpath(root, src)
                os.makedirs(os.path.join(dst, rel), exist_ok=True)
                for f in files:
                    if rel == "." and (f == ".lock" or (f == "config.toml" and keep_config)):
                        continue    # the device's run lock, or its config (engine.device = "gpu")
                    shutil.copy2(os.path.join(root, f), os.path.join(dst, rel, f))
        to_commit += [os.path.normpath(p) for p in _results(dst)]
    return removed, to_commit


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("pack")
    p.add_argument("runs")
    p.add_argument("tables", nargs="+")
    p.add_argument("--config")
    p.add_argument("--into", default=".devdata/rows")
    u = sub.add_parser("unpack")
    u.add_argument("runs")
    u.add_argument("archives", nargs="+")
    a = ap.parse_args(argv)
    if a.what == "pack":
        packed = pack(a.runs, a.tables, a.config, a.into)
        for name, how in packed.items():
            print(f"device_rows: {name}: {how}")
        size = sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(a.into) for f in fs)
        print(f"device_rows: {len(packed)} rows in {a.into} ({size / 2**20:.1f} MiB; carry it, ROWS_FROM={a.into})")
        return 0
    removed, to_commit = unpack(a.runs, a.archives)
    gone = [p for p in removed if _tracked(p)]
    print("device_rows: to track the rows as they came back (a finished row: analyse it here first, "
          "`mpdem analyze RUN --no-plots --packing`, for this machine's paths in its summaries):")
    if gone:
        print("  git rm -q --cached " + " ".join(gone))
    print("  git add -f " + " ".join(to_commit))
    return 0


if __name__ == "__main__":
    sys.exit(main())
