"""``mpdem analyze``: every measurement of docs/model.md section 6 on one state file.

::

    RUN/analysis/summary.json     the numbers (schema below), for people and for ``collect``
    RUN/analysis/profile.csv      phi(z) and z(z) with and without rattlers, per height bin
    RUN/analysis/coordination.csv P(z) with and without rattlers
    RUN/analysis/gofr.csv         g(r), linear bins up to analysis.g_r_max
    RUN/analysis/gofr_near.csv    g(r) on logarithmic bins in xi = r/d - 1
    RUN/analysis/zeta.csv         P(zeta) (and F_t/F_n for mu >= 1), frictional runs
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

from .. import checkpoint, config, rundir
from ..checkpoint import StateFileError
from ..errors import MpdemError
from . import bulk, fits, gofr, mobilisation

SUMMARY = "summary.json"


class AnalysisError(MpdemError, ValueError):
    """A file or a setting the analysis cannot use."""


def locate(target, out=None):
    """(state file, output directory) of ``mpdem analyze TARGET``.

    A run directory gives its final.h5 and RUN/analysis; a snapshot or
    checkpoint of a run gives RUN/analysis/<name>; RUN/final.h5 gives
    RUN/analysis; any other file gives <name>-analysis beside it.
    """
    if os.path.isdir(target):
        path = rundir.final_path(target)
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
        if not sub and os.path.basename(path) != "final.h5":
            run = None
    else:
        raise AnalysisError(f"{target}: no such file or directory")
    if out:
        return path, out
    stem = os.path.splitext(os.path.basename(path))[0]
    if run is None:
        return path, os.path.join(os.path.dirname(os.path.abspath(path)), f"{stem}-analysis")
    return path, os.path.join(run, "analysis", "" if stem == "final" else stem).rstrip(os.sep)


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


def _range(want, L_x, L_y, z1, z2, dr, name, warns):
    """A g(r) range below half the box that leaves a core slab a third of the bulk."""
    cap = min(0.5 * min(L_x, L_y), (z2 - z1) / 3.0)
    if want < cap:
        return want
    got = dr * math.floor((cap - 1e-9) / dr)
    if got <= 1.0:
        warns.append(f"no g(r): the bulk slab [{z1:.3g}, {z2:.3g}] is too thin for g(r) beyond contact "
                     f"(it needs more than 3 d); lower analysis.margin_bottom and analysis.margin_top")
        return None
    warns.append(f"analysis.{name} = {want:g} d cut to {got:g} d (half the box is {0.5 * min(L_x, L_y):g} d, "
                 f"a third of the bulk slab {(z2 - z1) / 3:.3g} d)")
    return got


def _profile(pk, reg):
    """Per-height-bin z with and without rattlers (mobile spheres) on the phi(z) grid."""
    edges = reg["edges"]
    zc = pk.x[:, 2]
    k = np.floor((zc - edges[0]) / (edges[1] - edges[0])).astype(np.int64)
    nb = len(edges) - 1
    ok = pk.mobile & (k >= 0) & (k < nb)
    n_all = np.bincount(k[ok], minlength=nb)
    z_all = np.bincount(k[ok], weights=pk.counts[ok], minlength=nb)
    ok_nr = ok & pk.kept
    n_nr = np.bincount(k[ok_nr], minlength=nb)
    z_nr = np.bincount(k[ok_nr], weights=pk.counts_nr[ok_nr], minlength=nb)
    with np.errstate(invalid="ignore", divide="ignore"):
        return n_all, z_all / n_all, z_nr / n_nr


def _csv(path, header, cols):
    """Columns (equal lengths) as a CSV file (``rundir.write_csv``)."""
    rundir.write_csv(path, header, zip(*cols))


def _finite(obj):
    """JSON-safe: nan and inf become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def measure(arrays, attrs, cfg):
    """All section 6 measurements of one state.

    Parameters
    ----------
    arrays : dict of a state sorted by id (``checkpoint.read_state``): id, x
        (n, 3), fixed (n,), and with a contact list id_i, id_j, F_n, F_t
    attrs : the file's attributes (L_x, L_y)
    cfg : Config (contact.*, analysis.*)

    Returns
    -------
    summary : dict (JSON-ready, see docs/analysis.md)
    tables : dict of arrays for the CSV files and plots
    """
    a, c = cfg.analysis, cfg.contact
    L_x, L_y = float(attrs["L_x"]), float(attrs["L_y"])
    warns = []
    pk = bulk.Packing(arrays["x"], arrays["fixed"], L_x, L_y, c.mu, a.n_min)
    reg = pk.region(a.margin_bottom, a.margin_top, a.profile_bin, a.tall_pile)
    z1, z2 = reg["z1"], reg["z2"]
    s = {k: v for k, v in reg.items() if k not in ("edges", "phi_z")}
    s["n_min"] = pk.n_min
    s.update(pk.measure(z1, z2))
    # docs/model.md 6.1.4: the same with both margins halved
    half = bulk.bulk_region(pk.x[pk.mobile, 2], pk.z_bed, L_x, L_y, 0.5 * reg["margin_bottom"],
                            0.5 * reg["margin_top"], a.profile_bin)
    s["halved_margins"] = dict(pk.measure(half["z1"], half["z2"]), z1=half["z1"], z2=half["z2"])

    tables = {"profile": reg, "z_profile": _profile(pk, reg),
              "packing": {"x": pk.x, "fixed": pk.fixed, "counts": pk.counts, "L_x": L_x, "L_y": L_y,
                          "z_bed": pk.z_bed}}
    s.update(alpha=math.nan, alpha_err=math.nan, alpha_fit=None, gofr=None)
    r_full = _range(a.g_r_max, L_x, L_y, z1, z2, a.g_dr, "g_r_max", warns)
    r_near = _range(a.near_r_max, L_x, L_y, z1, z2, a.g_dr, "near_r_max", warns)
    if r_full is not None and r_near is not None:
        xm = pk.x[pk.mobile]
        g = gofr.radial_distribution(xm, L_x, L_y, z1, z2, r_full, a.g_dr, a.xi_min, a.xi_per_decade)
        near = gofr.radial_distribution(xm, L_x, L_y, z1, z2, r_near, a.g_dr, a.xi_min, a.xi_per_decade)
        xi_c = np.sqrt(near["xi_lo"] * near["xi_hi"])
        lo, hi = fits.fit_window(c.k_n, s["overlap_median"], a.fit_xi_hi, a.fit_xi_lo)
        if not lo < hi:
            warns.append(f"fit window empty: xi_lo = {lo:.3g} (20 x median overlap) >= xi_hi = {hi:.3g}")
        pl = fits.power_law(xi_c, near["g_xi"], lo, hi)
        if not math.isfinite(pl["alpha"]):
            warns.append(f"power law not fitted: {pl['n_bins']} populated bins in [{lo:.3g}, {hi:.3g}]")
        s.update(alpha=pl["alpha"], alpha_err=pl["alpha_err"], alpha_fit=pl)
        s["gofr"] = {"r_max": g["r_max"], "n_ref": g["n_ref"], "rho": g["rho"],
                     "near_r_max": near["r_max"], "near_n_ref": near["n_ref"],
                     "near_contacts_per_ref": near["n_overlap"] / near["n_ref"]}
        tables.update(gofr=g, near=near, xi_c=xi_c, fit=pl)
    s["zeta"] = None
    if c.mu == 0:
        s["zeta_note"] = "mu = 0: no tangential forces"
    elif "id_i" not in arrays:
        s["zeta_note"] = f"no contact forces in a {attrs.get('kind', '?')} file (snapshots and final.h5 have them)"
    else:
        sel = mobilisation.bulk_contacts(arrays, arrays["id"], pk.x[:, 2], z1, z2)
        fr = mobilisation.force_ratios(arrays["F_n"][sel], arrays["F_t"][sel], c.mu, a.zeta_bins, a.mobilised)
        s["zeta"] = {k: fr[k] for k in ("n_contacts", "n_tensile", "n_above_one", "mobilised_fraction",
                                        "zeta_mean", "zeta_max", "n_ratio_above_one") if k in fr}
        tables["zeta"] = fr
    s["warnings"] = warns
    return s, tables


def write_tables(out, s, t):
    """The CSV files of one analysis."""
    reg = t["profile"]
    n_all, z_all, z_nr = t["z_profile"]
    _csv(os.path.join(out, "profile.csv"), ["z_lo", "z_hi", "phi", "n_particles", "z", "z_no_rattlers"],
         [reg["edges"][:-1], reg["edges"][1:], reg["phi_z"], n_all, z_all, z_nr])
    n = np.arange(len(s["P_z"]))
    _csv(os.path.join(out, "coordination.csv"), ["n", "P", "P_no_rattlers"], [n, s["P_z"], s["P_z_no_rattlers"]])
    if "zeta" in t:
        z = t["zeta"]
        cols, head = [z["edges"][:-1], z["edges"][1:], z["count"], z["P_zeta"]], ["zeta_lo", "zeta_hi", "count", "P"]
        if "P_ratio" in z:
            cols += [z["count_ratio"], z["P_ratio"]]
            head += ["count_ratio", "P_ratio"]
        _csv(os.path.join(out, "zeta.csv"), head, cols)
    if "gofr" not in t:
        return
    g = t["gofr"]
    _csv(os.path.join(out, "gofr.csv"), ["r_lo", "r_hi", "count", "g"], [g["r_lo"], g["r_hi"], g["count"], g["g"]])
    nr = t["near"]
    _csv(os.path.join(out, "gofr_near.csv"), ["xi_lo", "xi_hi", "xi", "count", "g"],
         [nr["xi_lo"], nr["xi_hi"], t["xi_c"], nr["count_xi"], nr["g_xi"]])


def analyze(target, out=None, sets=(), plots=True, log=print):
    """Analyse a run directory or a state file; returns (summary, output directory)."""
    t0 = time.perf_counter()
    path, out = locate(target, out)
    attrs = checkpoint.read_attrs(path)
    cfg = file_config(attrs, path, sets)
    arrays, attrs = checkpoint.read_state(path, pairs=True)
    t_read = time.perf_counter() - t0
    try:
        s, tables = measure(arrays, attrs, cfg)
    except ValueError as e:
        raise AnalysisError(f"{path}: {e}") from None
    s = {"source": os.path.abspath(path), "kind": attrs.get("kind"), "step": int(attrs.get("step", 0)),
         "time": float(attrs.get("time", 0.0)), "converged": bool(attrs.get("converged", False)),
         "written_by_ranks": int(attrs.get("ranks", 1)), "n": int(len(arrays["id"])),
         # the parameter set (config.PARAM_KEYS, what the across-runs tables group by) and the physics
         "params": {k: cfg.values[k] for k in config.PARAM_KEYS},
         "physics": {k: cfg.values[k] for k in config.PHYSICS_KEYS},
         "settings": {k: v for k, v in cfg.values.items() if k.startswith("analysis.")}, **s}
    os.makedirs(out, exist_ok=True)
    write_tables(out, s, tables)
    if plots:
        from . import plots as pl
        pl.run_plots(out, s, tables)
    s["seconds"] = {"read": t_read, "total": time.perf_counter() - t0}
    rundir.write_atomic(os.path.join(out, SUMMARY), json.dumps(_finite(s), indent=1) + "\n")
    for w in s["warnings"]:
        log(f"warning: {w}")
    log(describe(s))
    log(f"wrote {out}/ ({SUMMARY}, tables{' and plots' if plots else ''}) in {s['seconds']['total']:.1f} s")
    return s, out


def describe(s):
    """A few lines of the main numbers."""
    al = (f"alpha = {s['alpha']:.3f} +- {s['alpha_err']:.3f} (xi in [{s['alpha_fit']['xi_lo']:.2g}, "
          f"{s['alpha_fit']['xi_hi']:.2g}], {s['alpha_fit']['n_bins']} bins)"
          if math.isfinite(s["alpha"]) else "alpha: not fitted")
    zt = (f"; P(zeta): {s['zeta']['n_contacts']} bulk contacts, {100 * s['zeta']['mobilised_fraction']:.1f}% fully mobilised"
          if s.get("zeta") else "")
    return (f"bulk z in [{s['z1']:.2f}, {s['z2']:.2f}] ({s['n_bulk']} particles): z = {s['z']:.3f}, "
            f"without rattlers {s['z_no_rattlers']:.3f} ({100 * s['rattler_fraction']:.1f}% rattlers), "
            f"phi = {s['phi']:.4f}\n"
            f"margins halved: z = {s['halved_margins']['z']:.3f}, phi = {s['halved_margins']['phi']:.4f}\n"
            f"{al}{zt}")


__all__ = ["analyze", "locate", "measure", "file_config", "AnalysisError", "StateFileError"]
