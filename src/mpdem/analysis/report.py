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
from . import backbone, bands, bulk, contacts, fits, gofr, mobilisation, nearcontact, order

SUMMARY = "summary.json"
PACKING = "packing.npz"     # a run's kept packing (``mpdem export --format packing``) when final.h5 is gone


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


def isostatic(pk, cf, live, kept, bulk_rows, mu, mobilised):
    """The generalized isostatic count of a frictional packing (docs/model.md 6.2).

    Contacts at the Coulomb limit (zeta > ``mobilised``) remove a degree of
    freedom each: with N_m of them among N spheres, 3 N z / 2 - N_m = 6 N gives
    z_iso = 4 + 2 N_m / (3 N). Counted per sphere like z (each contact once for
    each of its two spheres, n_m = 2 N_m / N, over the bulk spheres) that is
    4 + n_m / 3, for all spheres and for the backbone. At mu = 0 it is 2 x 3 = 6.
    """
    if mu == 0:
        return {"z_iso": 6.0, "note": "mu = 0: isostatic z = 6 (2 x 3 degrees of freedom per sphere)"}
    if not cf.from_file.any():
        return {"note": "no contact forces in the file: no fully mobilised contacts to count"}
    mob = np.nan_to_num(cf.zeta, nan=0.0) > mobilised
    n = len(pk.x)
    per = np.bincount(pk.pairs[mob].ravel(), minlength=n)
    per_bb = np.bincount(pk.pairs[mob & live].ravel(), minlength=n)
    bk = bulk_rows & kept
    n_m = float(per[bulk_rows].mean()) if bulk_rows.any() else math.nan
    n_m_bb = float(per_bb[bk].mean()) if bk.any() else math.nan
    return {"n_m": n_m, "z_iso": 4.0 + n_m / 3.0, "n_m_backbone": n_m_bb,
            "z_iso_backbone": 4.0 + n_m_bb / 3.0, "mobilised": mobilised,
            "note": "z_iso = 4 + n_m / 3, n_m the fully mobilised contacts per sphere (each counted for both "
                    "of its spheres): 3 N z / 2 - N_m = 6 N"}


def _alpha(pk, z1, z2, a, overlap_median):
    """alpha by maximum likelihood on the windows, the default window and the local slope (6.5)."""
    lo, hi = fits.fit_window(a.fit_xi_hi, a.fit_xi_lo)
    wins = nearcontact.windows_of(a.alpha_windows)
    centres = nearcontact.slope_centres(*nearcontact.SLOPE_RANGE)
    reach = max([hi] + [w[1] for w in wins] + [c * 10 ** nearcontact.SLOPE_HALF_WIDTH for c in centres])
    refs = pk.in_slab(z1, z2)[pk.mobile]
    xi, w = nearcontact.gaps(pk.x[pk.mobile], refs, pk.L_x, pk.L_y, reach)
    soft = 20.0 * overlap_median

    def mark(st):
        # soft-sphere compression flattens g below ~20 x the typical overlap
        return dict(st, soft=bool(st["xi_lo"] < soft))

    return (mark(nearcontact.window_stats(xi, lo, hi, w)),
            [mark(nearcontact.window_stats(xi, w0, w1, w)) for w0, w1 in wins],
            nearcontact.local_slope(xi, centres, w), int(refs.sum()))


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
    z1, z2, h = reg["z1"], reg["z2"], reg["h"]
    cf = contacts.contact_forces(pk, arrays, c.k_n, c.mu, c.model)
    bb = backbone.of_packing(pk, cf, h, a.band_width, a.force_fraction)
    if a.rattlers == "force":
        pk.use_backbone(bb["kept"], bb["counts"])
    s = {k: v for k, v in reg.items() if k not in ("edges", "phi_z")}
    s["n_min"] = pk.n_min
    s.update(pk.measure(z1, z2))
    bulk_rows = pk.in_slab(z1, z2)
    bk = bulk_rows & bb["kept"]
    mid = 0.5 * (pk.x[pk.pairs[:, 0], 2] + pk.x[pk.pairs[:, 1], 2])
    in_slab = (mid >= z1) & (mid <= z2)
    s["backbone"] = {"z": float(bb["counts"][bk].mean()) if bk.any() else math.nan,
                     "rattler_fraction": float(1.0 - bk.sum() / max(bulk_rows.sum(), 1)),
                     "weak_fraction": float(bb["weak"][in_slab].mean()) if in_slab.any() else math.nan,
                     "force_fraction": a.force_fraction, "band_width": a.band_width,
                     "forces_from_file": float(cf.from_file.mean()) if len(cf.from_file) else math.nan,
                     "P_z": bulk.histogram_z(bb["counts"][bk]).tolist()}
    s["isostatic"] = isostatic(pk, cf, bb["live"], bb["kept"], bulk_rows, c.mu, a.mobilised)
    # docs/model.md 6.1.4: the same with both margins halved
    half = bulk.bulk_region(pk.x[pk.mobile, 2], pk.z_bed, L_x, L_y, 0.5 * reg["margin_bottom"],
                            0.5 * reg["margin_top"], a.profile_bin)
    s["halved_margins"] = dict(pk.measure(half["z1"], half["z2"]), z1=half["z1"], z2=half["z2"])
    Q6, crystal, _ = order.crystal_order(pk.x, L_x, L_y, a.order_cutoff, a.order_bond, a.order_bonds)
    s["order"] = {"Q6_mean": float(np.nanmean(Q6[bulk_rows])) if bulk_rows.any() else math.nan,
                  "crystal_fraction": float(crystal[bulk_rows].mean()) if bulk_rows.any() else math.nan,
                  "cutoff": a.order_cutoff, "bond": a.order_bond, "bonds": a.order_bonds}
    s["bands"] = bands.depth_profile(pk, cf, bb["kept"], bb["counts"], crystal, h, a.band_width, z1, z2)
    comp = in_slab & (cf.F_n > 0)
    s["P_f"] = bands.force_distribution(cf.F_n[comp] / bb["ref_force"][comp])

    tables = {"profile": reg, "z_profile": _profile(pk, reg),
              "packing": {"x": pk.x, "fixed": pk.fixed, "counts": pk.counts, "L_x": L_x, "L_y": L_y,
                          "z_bed": pk.z_bed}}
    s.update(alpha=math.nan, alpha_err=math.nan, alpha_fit=None, alpha_windows=[], alpha_local=[], gofr=None)
    dflt, wins, local, n_refs = _alpha(pk, z1, z2, a, s["overlap_median"])
    s.update(alpha=dflt["alpha"], alpha_err=dflt["alpha_err"], alpha_fit=dict(dflt, method="maximum likelihood",
             n_ref=n_refs), alpha_windows=wins, alpha_local=local)
    if not math.isfinite(dflt["alpha"]):
        warns.append(f"alpha not estimated: {dflt['n']} gaps in [{dflt['xi_lo']:.3g}, {dflt['xi_hi']:.3g}] "
                     f"(needs {nearcontact.N_MIN})")
    r_full = _range(a.g_r_max, L_x, L_y, z1, z2, a.g_dr, "g_r_max", warns)
    r_near = _range(a.near_r_max, L_x, L_y, z1, z2, a.g_dr, "near_r_max", warns)
    if r_full is not None and r_near is not None:
        xm = pk.x[pk.mobile]
        g = gofr.radial_distribution(xm, L_x, L_y, z1, z2, r_full, a.g_dr, a.xi_min, a.xi_per_decade)
        near = gofr.radial_distribution(xm, L_x, L_y, z1, z2, r_near, a.g_dr, a.xi_min, a.xi_per_decade)
        xi_c = np.sqrt(near["xi_lo"] * near["xi_hi"])
        s["gofr"] = {"r_max": g["r_max"], "n_ref": g["n_ref"], "rho": g["rho"],
                     "near_r_max": near["r_max"], "near_n_ref": near["n_ref"],
                     "near_contacts_per_ref": near["n_overlap"] / near["n_ref"]}
        tables.update(gofr=g, near=near, xi_c=xi_c, fit=s["alpha_fit"])
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
    s = {"source": source, "kind": attrs.get("kind"), "step": int(attrs.get("step", 0)),
         "time": float(attrs.get("time", 0.0)), "converged": bool(attrs.get("converged", False)),
         "written_by_ranks": int(attrs.get("ranks", 1)), "n": int(len(arrays["id"])),
         # the parameter set (config.PARAM_KEYS, what the across-runs tables group by) and the physics
         "params": {k: cfg.values[k] for k in config.PARAM_KEYS},
         "physics": {k: cfg.values[k] for k in config.PHYSICS_KEYS},
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
    s["seconds"] = {"read": t_read, "total": time.perf_counter() - t0}
    write(out, s, tables, plots, log)
    return s, out


def describe(s):
    """A few lines of the main numbers."""
    al = (f"alpha = {s['alpha']:.3f} +- {s['alpha_err']:.3f} (maximum likelihood, {s['alpha_fit']['n']} gaps "
          f"in xi [{s['alpha_fit']['xi_lo']:.2g}, {s['alpha_fit']['xi_hi']:.2g}]); "
          + ", ".join(f"[{w['xi_lo']:.0e}, {w['xi_hi']:.0e}]: {w['alpha']:.3f}" for w in s["alpha_windows"])
          if math.isfinite(s["alpha"]) else "alpha: not estimated")
    zt = (f"; P(zeta): {s['zeta']['n_contacts']} bulk contacts, "
          f"{100 * s['zeta']['mobilised_fraction']:.1f}% fully mobilised" if s.get("zeta") else "")
    iso = s.get("isostatic") or {}
    zi = (f"; generalized isostatic 4 + 2 n_m / 3 = {iso['z_iso']:.3f}" if "n_m" in iso else "")
    return (f"bulk z in [{s['z1']:.2f}, {s['z2']:.2f}] ({s['n_bulk']} particles): z = {s['z']:.3f}, "
            f"without rattlers ({s['rattlers']} rule) {s['z_no_rattlers']:.3f} "
            f"({100 * s['rattler_fraction']:.1f}% rattlers), backbone z = {s['backbone']['z']:.3f}{zi}, "
            f"phi = {s['phi']:.4f}\n"
            f"margins halved: z = {s['halved_margins']['z']:.3f}, phi = {s['halved_margins']['phi']:.4f}; "
            f"crystal-like {100 * s['order']['crystal_fraction']:.1f}%\n"
            f"{al}{zt}")


__all__ = ["analyze", "locate", "measure", "file_config", "AnalysisError", "StateFileError"]
