"""``mpdem analyze RUN --series``: how a run settled, one row per snapshot.

Every snapshot of a run (``RUN/snapshots/snap-NNNNN.h5``, written every
``output.snapshot_every`` steps) and its final state are measured: bulk z
(with and without rattlers), bulk phi, the contacts per mobile sphere over
the whole pile and the kinetic energy per mobile sphere. The table goes to
``RUN/analysis/series.csv``, and a plot of it against time, with the run's
``thermo.csv`` E_k, to ``RUN/analysis/series.png``. A user sees z stop
changing (or not) before the run stops, and can judge the stop rule.
"""
from __future__ import annotations

import csv
import math
import os

import numpy as np

from ..io import checkpoint
from ..io import rundir
from ..kernels.particle import HALF_I
from . import bulk
from .report import AnalysisError, file_config

COLUMNS = ("step", "time", "kind", "ek", "ek_trans", "ek_rot", "contacts_per_particle",
           "z", "z_no_rattlers", "phi", "n_bulk", "z1", "z2", "note")


def files(run_dir):
    """State files of a run in time order: its snapshots, then final.h5 if there is one."""
    if not os.path.isdir(run_dir):
        raise AnalysisError(f"{run_dir}: not a run directory")
    out = [p for _, p in rundir.snapshots(run_dir)]
    final = rundir.final_path(run_dir)
    if os.path.exists(final):
        out.append(final)
    if not out:
        raise AnalysisError(f"{run_dir}: no snapshots and no final.h5 to measure; run with "
                            f"--set output.snapshot_every=STEPS to record the settling")
    return out


def measure_file(path, sets=()):
    """One row of the series (a dict of COLUMNS) for one state file."""
    arrays, attrs = checkpoint.read_state(path)
    cfg = file_config(attrs, path, sets)
    a = cfg.analysis
    mob = ~arrays["fixed"].astype(bool)
    n = max(int(mob.sum()), 1)
    ek_t = 0.5 * float(np.sum(arrays["v"][mob] ** 2)) / n
    ek_r = HALF_I * float(np.sum(arrays["omega"][mob] ** 2)) / n
    row = dict.fromkeys(COLUMNS, math.nan)
    row.update(step=int(attrs.get("step", 0)), time=float(attrs.get("time", 0.0)), kind=attrs.get("kind", "?"),
               ek=ek_t + ek_r, ek_trans=ek_t, ek_rot=ek_r, note="")
    pk = bulk.Packing(arrays["x"], arrays["fixed"], attrs["L_x"], attrs["L_y"], cfg.contact.mu, a.n_min)
    row["contacts_per_particle"] = float(pk.counts[pk.mobile].mean())
    try:
        reg = pk.region(a.margin_bottom, a.margin_top, a.profile_bin, a.tall_pile)
    except ValueError as e:           # still pouring: no pile to take a bulk of
        row["note"] = str(e)
        return row
    m = pk.measure(reg["z1"], reg["z2"])
    row.update(z=m["z"], z_no_rattlers=m["z_no_rattlers"], phi=m["phi"], n_bulk=m["n_bulk"],
               z1=reg["z1"], z2=reg["z2"])
    return row


def series(run_dir, sets=(), out=None, plots=True, log=print):
    """Measure every snapshot of ``run_dir``; write series.csv (and series.png).

    Returns
    -------
    (rows, out): list of dicts with COLUMNS, and the output directory (default RUN/analysis).
    """
    paths = files(run_dir)
    rows = []
    for p in paths:
        rows.append(measure_file(p, sets))
        r = rows[-1]
        log(f"series: {os.path.basename(p)}: step {r['step']}, t {r['time']:.4g}, E_k {r['ek']:.3g}, "
            f"z {r['z']:.4f}, phi {r['phi']:.4f}" + (f" ({r['note']})" if r["note"] else ""))
    out = out or os.path.join(run_dir, "analysis")
    os.makedirs(out, exist_ok=True)
    tmp = os.path.join(out, "series.csv.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([r[c] if not isinstance(r[c], float) else f"{r[c]:.10g}" for c in COLUMNS])
    os.replace(tmp, os.path.join(out, "series.csv"))
    if plots:
        plot(os.path.join(out, "series.png"), rows, thermo(run_dir))
    log(f"series: wrote {out}/series.csv" + (" and series.png" if plots else "") + f" ({len(rows)} states)")
    return rows, out


def thermo(run_dir):
    """(time, ek) of the run's thermo.csv, or None."""
    path = os.path.join(run_dir, "thermo.csv")
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
        return np.atleast_1d(data["time"]), np.atleast_1d(data["ek"])
    except (OSError, ValueError):
        return None


def plot(path, rows, th=None):
    """E_k (log), bulk z and bulk phi against time, in three panels sharing the time axis."""
    from .plots import plt, save
    t = np.array([r["time"] for r in rows])
    fig, ax = plt.subplots(3, 1, figsize=(6.5, 7.5), sharex=True)
    if th is not None:
        ax[0].semilogy(th[0], np.where(th[1] > 0, th[1], np.nan), lw=0.6, color="0.6", label="thermo.csv")
    ax[0].semilogy(t, [r["ek"] for r in rows], "o", ms=3, label="snapshots")
    ax[0].set_ylabel("E_k / N [m g d]")
    ax[0].legend(fontsize=8)
    ax[1].plot(t, [r["z"] for r in rows], "o-", ms=3, label="z")
    ax[1].plot(t, [r["z_no_rattlers"] for r in rows], "s--", ms=3, label="z without rattlers")
    ax[1].set_ylabel("bulk z")
    ax[1].legend(fontsize=8)
    ax[2].plot(t, [r["phi"] for r in rows], "o-", ms=3)
    ax[2].set_ylabel("bulk phi")
    ax[2].set_xlabel("t [tau]")
    for a in ax:
        a.grid(alpha=0.3)
    save(fig, path)
