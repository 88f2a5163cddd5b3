"""``mpdem analyze``: every measurement of docs/model.md section 6 on one state file.

::

    RUN/analysis/summary.json     the numbers (schema below), for people and for ``collect``
    RUN/analysis/profile.csv      phi(z) and z(z) with and without rattlers, per height bin
    RUN/analysis/coordination.csv P(z) with and without rattlers
    RUN/analysis/gofr.csv         g(r), linear bins up to analysis.g_r_max
    RUN/analysis/gofr_near.csv    g(r) on logarithmic bins in xi = r/d - 1
    RUN/analysis/zeta.csv         P(zeta) (and F_t/F_n for mu >= 1), frictional runs
    RUN/analysis/bands.csv        the depth profile: z, backbone z, phi, overlap, sigma_zz, crystal fraction per band
    RUN/analysis/P_f.csv          P(f), f = F_n / the mean F_n of its depth band, bulk contacts
    RUN/analysis/alpha_local.csv  the local slope: alpha on half-decade windows of xi
    RUN/analysis/*.png            the same as plots

A snapshot ``RUN/snapshots/snap-NNNNN.h5`` is analysed into
``RUN/analysis/snap-NNNNN/``. Files are written under a temporary name and
renamed. The analysis runs in one process (its kernels use numba threads).
"""
from __future__ import annotations

import json
import math
import os
import time
import tomllib

import numpy as np

from ..io import checkpoint, packing
from .. import config
from ..io import rundir
from ..io.checkpoint import StateFileError
from ..errors import AnalysisError
from . import bands, bulk, flow
from .measures import measure

SUMMARY = "summary.json"
PACKING = "packing.npz"     # a run's kept packing (``mpdem export --format packing``) when final.h5 is gone
# The version of the measures a summary holds: raise it when a measure's definition or a summary's
# keys change, so that ``mpdem collect`` analyses again every summary written before (0: unversioned).
MEASURES_VERSION = 1
# what a packing cannot measure again: the flow of the velocities it does not keep, and the steadiness of a
# thermo table that is not kept beside it; analysed again, a run keeps these from its earlier analysis
CARRIED = ("flow", "flow_steady")


def locate(target, out=None):
    """(state file, output directory) of ``mpdem analyze TARGET``.

    A run directory gives its final.h5 (or, without one, its packing.npz) and
    RUN/analysis; a snapshot or
    checkpoint of a run gives RUN/analysis/<name>; RUN/final.h5 gives
    RUN/analysis; any other file gives <name>-analysis beside it.
    """
    if os.path.isdir(target):
        path = rundir.final_path(target)
        if not os.path.exists(path) and os.path.exists(os.path.join(target, PACKING)):
            path = os.path.join(target, PACKING)
        if not os.path.exists(path):
            snaps = rundir.snapshots(target)
            hint = (f"; analyse a snapshot instead, e.g. {snaps[-1][1]}" if snaps else "")
            raise AnalysisError(f"{target}: no final.h5 (the run has not finished){hint}")
        run = target
    elif os.path.exists(target):
        path = target
        d = os.path.dirname(os.path.abspath(target))
        sub = os.path.basename(d) in (rundir.CKPT_DIR, rundir.SNAP_DIR)
        run = os.path.dirname(d) if sub else d
        if not sub and os.path.basename(path) not in ("final.h5", PACKING):
            run = None
    else:
        raise AnalysisError(f"{target}: no such file or directory")
    if out:
        return path, out
    stem = os.path.splitext(os.path.basename(path))[0]
    if run is None:
        return path, os.path.join(os.path.dirname(os.path.abspath(path)), f"{stem}-analysis")
    return path, os.path.join(run, "analysis", "" if stem in ("final", "packing") else stem).rstrip(os.sep)


def file_config(attrs, path, sets=()):
    """The Config of a state file, with ``--set analysis.*`` applied."""
    if "config" not in attrs:
        raise AnalysisError(f"{path}: no run config in the file (attribute 'config'); "
                            f"analyze needs the run's contact parameters")
    try:
        raw = config.flatten(tomllib.loads(attrs["config"]), origin=path)
    except (tomllib.TOMLDecodeError, config.ConfigError) as e:
        raise AnalysisError(f"{path}: its config is unusable ({e})") from None
    for item in sets:
        key, value = config.parse_set(item)
        if not key.startswith("analysis."):
            raise config.ConfigError(f"--set {key}: analyze can change only analysis.* keys "
                                     f"(the physics of the file is fixed)")
        raw[key] = value
    return config.resolve(raw)


def _csv(path, header, cols):
    """Columns (equal lengths) as a CSV file (``rundir.write_csv``)."""
    rundir.write_csv(path, header, zip(*cols))


def zeta_table(z):
    """(header, columns) of zeta.csv from ``mobilisation.force_ratios``'s dict: P(zeta) on its bins, and
    F_t/F_n on the same bins for mu >= 1 (``campaign.ratio`` reads ``count_ratio``)."""
    cols, head = [z["edges"][:-1], z["edges"][1:], z["count"], z["P_zeta"]], ["zeta_lo", "zeta_hi", "count", "P"]
    if "P_ratio" in z:
        cols += [z["count_ratio"], z["P_ratio"]]
        head += ["count_ratio", "P_ratio"]
    return head, cols


def write_tables(out, s, t):
    """The CSV files of one analysis."""
    reg = t["profile"]
    n_all, z_all, z_nr = t["z_profile"]
    _csv(os.path.join(out, "profile.csv"), ["z_lo", "z_hi", "phi", "n_particles", "z", "z_no_rattlers"],
         [reg["edges"][:-1], reg["edges"][1:], reg["phi_z"], n_all, z_all, z_nr])
    n = np.arange(len(s["P_z"]))
    _csv(os.path.join(out, "coordination.csv"), ["n", "P", "P_no_rattlers"], [n, s["P_z"], s["P_z_no_rattlers"]])
    if "zeta" in t:
        _csv(os.path.join(out, "zeta.csv"), *zeta_table(t["zeta"]))
    if "flow" in t:
        f = t["flow"]
        _csv(os.path.join(out, "flow.csv"), ["z_lo", "z_hi", "n", "phi", "v_x", "v_y", "v_z", "T"],
             [f["edges"][:-1], f["edges"][1:], f["n"], f["phi"], f["v_x"], f["v_y"], f["v_z"], f["T"]])
    b = s["bands"]
    cols = ["depth_lo", "depth_hi", "z_lo", "z_hi", "in_bulk", "n_particles", "z", "z_backbone", "rattler_fraction",
            "phi", "overlap_mean", "overlap_median", "F_n_mean", "sigma_zz", "crystal_fraction", "n_contacts"]
    _csv(os.path.join(out, "bands.csv"), cols, [b[c] for c in cols])
    pf = s["P_f"]
    edges = bands.F_BIN * np.arange(len(pf["counts"]) + 1)
    _csv(os.path.join(out, "P_f.csv"), ["f_lo", "f_hi", "count", "P"],
         [edges[:-1], edges[1:], pf["counts"], bands.density(pf["counts"], pf["n"])])
    _csv(os.path.join(out, "alpha_local.csv"), ["xi", "xi_lo", "xi_hi", "n", "alpha", "alpha_err"],
         [[w[k] for w in s["alpha_local"]] for k in ("xi", "xi_lo", "xi_hi", "n", "alpha", "alpha_err")])
    if "gofr" not in t:
        return
    g = t["gofr"]
    _csv(os.path.join(out, "gofr.csv"), ["r_lo", "r_hi", "count", "g"], [g["r_lo"], g["r_hi"], g["count"], g["g"]])
    nr = t["near"]
    _csv(os.path.join(out, "gofr_near.csv"), ["xi_lo", "xi_hi", "xi", "count", "g"],
         [nr["xi_lo"], nr["xi_hi"], t["xi_c"], nr["count_xi"], nr["g_xi"]])


def read(path, sets=()):
    """(arrays, attrs, cfg) of a state or packing file, with ``--set analysis.*`` items applied."""
    if packing.is_packing(path):
        arrays, attrs = packing.read(path)
        return arrays, attrs, file_config(attrs, path, sets)
    cfg = file_config(checkpoint.read_attrs(path), path, sets)
    arrays, attrs = checkpoint.read_state(path, pairs=True)
    return arrays, attrs, cfg


def summarise(arrays, attrs, cfg, source):
    """``measure`` with the file's particulars and the run's parameters: (summary, tables)."""
    try:
        s, tables = measure(arrays, attrs, cfg)
    except ValueError as e:
        raise AnalysisError(f"{source}: {e}") from None
    s = {"source": source, "measures_version": MEASURES_VERSION,
         "kind": attrs.get("kind"), "step": int(attrs.get("step", 0)),
         "time": float(attrs.get("time", 0.0)), "converged": bool(attrs.get("converged", False)),
         "written_by_ranks": int(attrs.get("ranks", 1)), "n": int(len(arrays["id"])),
         # the parameter set (config.PARAM_KEYS, what the across-runs tables group by) and the physics
         "params": {k: cfg.values[k] for k in config.PARAM_KEYS},
         "physics": {k: cfg.values[k] for k in config.PHYSICS_KEYS},
         # the sample: the pour's seed is params' run.seed; the bed's (bed.seed, or run.seed)
         "bed_seed": config.bed_seed(cfg),
         "settings": {k: v for k, v in cfg.values.items() if k.startswith("analysis.")}, **s}
    return s, tables


def arrays_of(s, t):
    """The curves of one analysis as arrays: g_r, g_xi, P_z, P_zeta (where measured), bands."""
    out = {"P_z": (np.arange(len(s["P_z"])), np.asarray(s["P_z"])),
           "bands": {k: np.asarray(v) for k, v in s["bands"].items()}}
    if "gofr" in t:
        g, nr = t["gofr"], t["near"]
        out["g_r"] = (0.5 * (g["r_lo"] + g["r_hi"]), g["g"])
        out["g_xi"] = (t["xi_c"], nr["g_xi"])
    if "zeta" in t:
        z = t["zeta"]
        out["P_zeta"] = (0.5 * (z["edges"][:-1] + z["edges"][1:]), z["P_zeta"])
    return out


def write(out, s, tables, plots=True, log=print):
    """The files of one analysis into ``out``: the tables, the plots and summary.json (written last)."""
    t0 = time.perf_counter()
    os.makedirs(out, exist_ok=True)
    write_tables(out, s, tables)
    if plots:
        from . import plots as pl
        pl.run_plots(out, s, tables)
    s.setdefault("seconds", {})["total"] = s.get("seconds", {}).get("total", 0.0) + time.perf_counter() - t0
    rundir.write_json(os.path.join(out, SUMMARY), s)
    for w in s["warnings"]:
        log(f"warning: {w}")
    log(describe(s))
    log(f"wrote {out}/ ({SUMMARY}, tables{' and plots' if plots else ''}) in {s['seconds']['total']:.1f} s")


def analyze(target, out=None, sets=(), plots=True, log=print, keep_packing=False):
    """``mpdem analyze``: a run directory or a state file measured and written; (summary, output directory).

    ``keep_packing``: when the state is a run's final.h5, also write RUN/packing.npz
    (``mpdem.io.packing``), which this function reads when final.h5 is gone.
    """
    t0 = time.perf_counter()
    path, out = locate(target, out)
    arrays, attrs, cfg = read(path, sets)
    t_read = time.perf_counter() - t0
    if keep_packing and os.path.basename(path) == "final.h5":
        packing.write(os.path.join(os.path.dirname(path), PACKING), arrays, attrs)
    s, tables = summarise(arrays, attrs, cfg, os.path.abspath(path))
    if os.path.basename(path) in ("final.h5", PACKING):
        # a flow-arrest run: was its flow steady before the incline dropped (docs/model.md 5.5)
        s["flow_steady"] = flow.steadiness(os.path.dirname(path), cfg)
    if os.path.basename(path) == PACKING:
        _carry(out, s)
    s["seconds"] = {"read": t_read, "total": time.perf_counter() - t0}
    write(out, s, tables, plots, log)
    return s, out


def _carry(out, s):
    """Keep in ``s`` (the summary of a packing.npz) the numbers of ``CARRIED`` that the earlier summary in
    ``out`` measured on the same state and the packing cannot; ``carried`` names them and their origin.
    The same state: the same step, time, sphere count, parameters and bed (an ``--out`` shared by runs
    that stopped at one step carries nothing between them)."""
    try:
        with open(os.path.join(out, SUMMARY)) as fh:
            old = json.load(fh)
    except (OSError, ValueError):
        return
    same = ("step", "time", "n", "params", "bed_seed")
    if not isinstance(old, dict) or any(rundir.json_safe(old.get(k)) != rundir.json_safe(s.get(k)) for k in same):
        return
    kept = [k for k in CARRIED if s.get(k) is None and old.get(k) is not None]
    for k in kept:
        s[k] = old[k]
    if "flow" in kept:
        s.pop("flow_note", None)
    if kept:
        before = old.get("carried") or {}
        s["carried"] = {"keys": kept, "from": before.get("from", old.get("source")),
                        "settings": before.get("settings", old.get("settings")),
                        "note": "measured on the run's state with velocities and its thermo table, which the "
                                "packing does not keep: kept from the earlier analysis of the same state "
                                "(with its analysis settings)"}


def describe(s):
    """A few lines of the main numbers."""
    al = (f"alpha = {s['alpha']:.3f} +- {s['alpha_err']:.3f} (maximum likelihood, {s['alpha_fit']['n']} gaps "
          f"in xi [{s['alpha_fit']['xi_lo']:.2g}, {s['alpha_fit']['xi_hi']:.2g}]); "
          + ", ".join(f"[{w['xi_lo']:.0e}, {w['xi_hi']:.0e}]: {w['alpha']:.3f}" for w in s["alpha_windows"])
          if math.isfinite(s["alpha"]) else "alpha: not estimated")
    zt = (f"; P(zeta): {s['zeta']['n_contacts']} bulk contacts, "
          f"{100 * s['zeta']['mobilised_fraction']:.1f}% fully mobilised" if s.get("zeta") else "")
    iso = s.get("isostatic") or {}
    zi = (f"; generalized isostatic 4 + n_m / 3 = {iso['z_iso']:.3f}" if "n_m" in iso else "")
    wins = [w for w in (s.get("depth_windows") or {}).get("windows", []) if w["complete"]]
    dw = ("\nz at depths below the surface (jackknife errors): "
          + ", ".join(f"{w['depth_lo']:g}-{w['depth_hi']:g} d {w['z']:.3f} +- {w['z_err']:.3f}" for w in wins)
          if wins else "")
    return (f"bulk z in [{s['z1']:.2f}, {s['z2']:.2f}] ({s['n_bulk']} particles): z = {s['z']:.3f}, "
            f"without rattlers ({s['rattlers']} rule) {bulk.rattlers_text(s)}, "
            f"backbone z = {s['backbone']['z']:.3f}{zi}, "
            f"phi = {s['phi']:.4f}\n"
            f"margins halved: z = {s['halved_margins']['z']:.3f}, phi = {s['halved_margins']['phi']:.4f}; "
            f"crystal-like {100 * s['order']['crystal_fraction']:.1f}%\n"
            f"{al}{zt}{dw}")


__all__ = ["analyze", "locate", "measure", "file_config", "AnalysisError", "StateFileError"]
