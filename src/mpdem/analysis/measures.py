"""The measurements of one packing, one row each of ``MEASURES`` (docs/model.md section 6).

``measure`` makes what every measurement reads once (the ``Packing``, its bulk slab, the contact
forces and the force backbone: a ``Sample``) and then runs the table in order; each row adds its
numbers to the summary (``summary.json``, docs/analysis.md) and its arrays to the tables that the
CSV files and the plots are made of. A new measurement is a function here and a row in the table;
a row may read what a row above it left (``bands`` reads the crystal fraction of ``order``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from . import (backbone, bands, bulk, contacts, fabric, fits, flow, gofr, jackknife, mobilisation, nearcontact, order,
               surface)
from .. import planes


@dataclass
class Sample:
    """One packing as every measurement reads it, and what the measurements made so far.

    Attributes
    ----------
    arrays, attrs, cfg
        The state (sorted by id), its file's attributes and the config (``measure``).
    pk : bulk.Packing
    reg : dict
        The bulk slab and the phi(z) profile (``Packing.region``): z1, z2, h [d], edges, phi_z.
    cf : contacts.ContactForces
    bb : dict
        The force backbone (``backbone.of_packing``): kept, counts, live, weak, ref_force.
    bulk_rows : (n,) bool
        Spheres in the slab.
    in_slab : (P,) bool
        Contacts whose midpoint is in the slab.
    summary : dict
        The summary so far (JSON-ready).
    tables : dict
        Arrays for the CSV files and the plots.
    warnings : list of str
    found : dict
        What a row leaves for the rows below it (``crystal``: order's crystal flags).
    """
    arrays: dict
    attrs: dict
    cfg: object
    pk: bulk.Packing
    reg: dict
    cf: object
    bb: dict
    bulk_rows: np.ndarray
    in_slab: np.ndarray
    summary: dict = field(default_factory=dict)
    tables: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    found: dict = field(default_factory=dict)

    @property
    def z1(self):
        return self.reg["z1"]

    @property
    def z2(self):
        return self.reg["z2"]


def sample(arrays, attrs, cfg):
    """The ``Sample`` of a state: the packing, its slab, contact forces and backbone."""
    a, c = cfg.analysis, cfg.contact
    pk = bulk.Packing(arrays["x"], arrays["fixed"], float(attrs["L_x"]), float(attrs["L_y"]), c.mu, a.n_min,
                      planes.of_config(cfg))
    reg = pk.region(a.margin_bottom, a.margin_top, a.profile_bin, a.tall_pile)
    cf = contacts.contact_forces(pk, arrays, c.k_n, c.mu, c.model)
    bb = backbone.of_packing(pk, cf, reg["h"], a.band_width, a.force_fraction)
    if a.rattlers == "force":
        pk.use_backbone(bb["kept"], bb["counts"])
    mid = 0.5 * (pk.x[pk.pairs[:, 0], 2] + pk.x[pk.pairs[:, 1], 2])
    return Sample(arrays, attrs, cfg, pk, reg, cf, bb, pk.in_slab(reg["z1"], reg["z2"]),
                  (mid >= reg["z1"]) & (mid <= reg["z2"]))


# -- the measurements: each reads the Sample and adds to its summary and tables --

def slab(m):
    """z, P(z) with and without rattlers, phi and the overlaps in the bulk slab (6.1)."""
    m.summary.update({k: v for k, v in m.reg.items() if k not in ("edges", "phi_z")})
    m.summary["n_min"] = m.pk.n_min
    m.summary.update(m.pk.measure(m.z1, m.z2))
    pk = m.pk
    m.tables.update(profile=m.reg, z_profile=_profile(pk, m.reg),
                    packing={"x": pk.x, "fixed": pk.fixed, "counts": pk.counts, "L_x": pk.L_x, "L_y": pk.L_y,
                             "z_bed": pk.z_bed})


def _backbone_numbers(m, bb):
    """z, rattler and weak-contact fractions of the backbone ``bb`` in the slab."""
    bk = m.bulk_rows & bb["kept"]
    return {"z": float(bb["counts"][bk].mean()) if bk.any() else math.nan,
            "rattler_fraction": float(1.0 - bk.sum() / max(m.bulk_rows.sum(), 1)),
            "weak_fraction": float(bb["weak"][m.in_slab].mean()) if m.in_slab.any() else math.nan}


def backbone_z(m):
    """z of the force backbone and its rattlers (6.3)."""
    a, bb, cf = m.cfg.analysis, m.bb, m.cf
    m.summary["backbone"] = dict(
        _backbone_numbers(m, bb), force_fraction=a.force_fraction, band_width=a.band_width,
        forces_from_file=float(cf.from_file.mean()) if len(cf.from_file) else math.nan,
        P_z=bulk.histogram_z(bb["counts"][m.bulk_rows & bb["kept"]]).tolist())


def backbone_cuts(m):
    """z of the backbone at several force cuts (6.10): how much of z - z_backbone is the cut's own."""
    a = m.cfg.analysis
    out = []
    for cut in a.backbone_cuts:
        # the run's own cut is the backbone already made
        bb = m.bb if cut == a.force_fraction else backbone.of_packing(m.pk, m.cf, m.reg["h"], a.band_width, cut)
        out.append(dict(force_fraction=cut, **_backbone_numbers(m, bb)))
    m.summary["backbone_cuts"] = out


def isostatic_count(m):
    """The generalized isostatic count of a frictional packing (6.2; ``isostatic``)."""
    m.summary["isostatic"] = isostatic(m.pk, m.cf, m.bb["live"], m.bb["kept"], m.bulk_rows, m.cfg.contact.mu,
                                       m.cfg.analysis.mobilised)


def halved_margins(m):
    """The slab's numbers with both margins halved (6.1.4)."""
    pk, reg = m.pk, m.reg
    half = bulk.bulk_region(pk.x[pk.mobile, 2], pk.z_bed, pk.L_x, pk.L_y, 0.5 * reg["margin_bottom"],
                            0.5 * reg["margin_top"], m.cfg.analysis.profile_bin)
    m.summary["halved_margins"] = dict(pk.measure(half["z1"], half["z2"]), z1=half["z1"], z2=half["z2"])


def crystal_order(m):
    """Q6 and the crystal fraction in the slab (6.7)."""
    a, rows = m.cfg.analysis, m.bulk_rows
    Q6, crystal, _ = order.crystal_order(m.pk.x, m.pk.L_x, m.pk.L_y, a.order_cutoff, a.order_bond, a.order_bonds)
    m.found["crystal"] = crystal
    m.summary["order"] = {"Q6_mean": float(np.nanmean(Q6[rows])) if rows.any() else math.nan,
                          "crystal_fraction": float(crystal[rows].mean()) if rows.any() else math.nan,
                          "cutoff": a.order_cutoff, "bond": a.order_bond, "bonds": a.order_bonds}


def depth_bands(m):
    """The depth profile in bands of ``analysis.band_width`` (6.1.3)."""
    a = m.cfg.analysis
    m.summary["bands"] = bands.depth_profile(m.pk, m.cf, m.bb["kept"], m.bb["counts"], m.found["crystal"],
                                             m.reg["h"], a.band_width, m.z1, m.z2)


def force_distribution(m):
    """P(f), f = F_n over its depth band's mean, bulk contacts (6.4)."""
    comp = m.in_slab & (m.cf.F_n > 0)
    m.summary["P_f"] = bands.force_distribution(m.cf.F_n[comp] / m.bb["ref_force"][comp])


def alpha(m):
    """alpha by maximum likelihood on the default window and the others, and the local slope (6.5)."""
    s, a, pk = m.summary, m.cfg.analysis, m.pk
    s.update(alpha=math.nan, alpha_err=math.nan, alpha_fit=None, alpha_windows=[], alpha_local=[])
    lo, hi = fits.fit_window(a.fit_xi_hi, a.fit_xi_lo)
    wins = nearcontact.windows_of(a.alpha_windows)
    centres = nearcontact.slope_centres(*nearcontact.SLOPE_RANGE)
    reach = max([hi] + [w[1] for w in wins] + [c * 10 ** nearcontact.SLOPE_HALF_WIDTH for c in centres])
    refs = pk.in_slab(m.z1, m.z2)[pk.mobile]
    xi, w = nearcontact.gaps(pk.x[pk.mobile], refs, pk.L_x, pk.L_y, reach)
    # soft-sphere compression flattens g below ~20 x the typical overlap
    soft = 20.0 * s["overlap_median"]

    def stats(lo, hi):
        st = nearcontact.window_stats(xi, lo, hi, w)
        return dict(st, soft=bool(st["xi_lo"] < soft))

    dflt = stats(lo, hi)
    s.update(alpha=dflt["alpha"], alpha_err=dflt["alpha_err"],
             alpha_fit=dict(dflt, method="maximum likelihood", n_ref=int(refs.sum())),
             alpha_windows=[stats(w0, w1) for w0, w1 in wins], alpha_local=nearcontact.local_slope(xi, centres, w))
    if not math.isfinite(dflt["alpha"]):
        m.warnings.append(f"alpha not estimated: {dflt['n']} gaps in [{dflt['xi_lo']:.3g}, {dflt['xi_hi']:.3g}] "
                          f"(needs {nearcontact.N_MIN})")


def radial_distribution(m):
    """g(r) on linear bins and near contact on logarithmic bins of xi (6.6)."""
    a, pk = m.cfg.analysis, m.pk
    m.summary["gofr"] = None
    r_full = _range(a.g_r_max, pk.L_x, pk.L_y, m.z1, m.z2, a.g_dr, "g_r_max", m.warnings)
    r_near = _range(a.near_r_max, pk.L_x, pk.L_y, m.z1, m.z2, a.g_dr, "near_r_max", m.warnings)
    if r_full is None or r_near is None:
        return
    xm = pk.x[pk.mobile]
    g = gofr.radial_distribution(xm, pk.L_x, pk.L_y, m.z1, m.z2, r_full, a.g_dr, a.xi_min, a.xi_per_decade)
    near = gofr.radial_distribution(xm, pk.L_x, pk.L_y, m.z1, m.z2, r_near, a.g_dr, a.xi_min, a.xi_per_decade)
    m.summary["gofr"] = {"r_max": g["r_max"], "n_ref": g["n_ref"], "rho": g["rho"],
                         "near_r_max": near["r_max"], "near_n_ref": near["n_ref"],
                         "near_contacts_per_ref": near["n_overlap"] / near["n_ref"]}
    m.tables.update(gofr=g, near=near, xi_c=np.sqrt(near["xi_lo"] * near["xi_hi"]), fit=m.summary["alpha_fit"])


def force_ratios(m):
    """P(zeta), zeta = |F_t| / (mu F_n), of the bulk contacts of a frictional packing (6.4)."""
    s, c, a, arrays = m.summary, m.cfg.contact, m.cfg.analysis, m.arrays
    s["zeta"] = None
    if c.mu == 0:
        s["zeta_note"] = "mu = 0: no tangential forces"
    elif "id_i" not in arrays:
        s["zeta_note"] = f"no contact forces in a {m.attrs.get('kind', '?')} file (snapshots and final.h5 have them)"
    else:
        sel = mobilisation.bulk_contacts(arrays, arrays["id"], m.pk.x[:, 2], m.z1, m.z2)
        fr = mobilisation.force_ratios(arrays["F_n"][sel], arrays["F_t"][sel], c.mu, a.zeta_bins, a.mobilised)
        s["zeta"] = {k: fr[k] for k in ("n_contacts", "n_tensile", "n_above_one", "mobilised_fraction",
                                        "zeta_mean", "zeta_max", "n_ratio_above_one") if k in fr}
        m.tables["zeta"] = fr


def depth_windows(m):
    """z, z without rattlers, phi and alpha on fixed windows of depth below the free surface, with
    jackknife errors over lateral columns (6.10); a window deeper than the slab's bottom margin is
    not measured (``complete`` false): piles of any height are compared at the same depths."""
    a, pk = m.cfg.analysis, m.pk
    k = a.jackknife_columns
    K = k * k
    col = jackknife.columns(pk.x, pk.L_x, pk.L_y, k)
    zm, mob_col = pk.x[pk.mobile, 2], col[pk.mobile]
    lo, hi = fits.fit_window(a.fit_xi_hi, a.fit_xi_lo)
    out = []
    for win in _windows(m):
        if not win["complete"]:
            out.append(win)
            continue
        d_lo, d_hi, z1, z2 = win["depth_lo"], win["depth_hi"], win["z1"], win["z2"]
        rows = pk.in_slab(z1, z2)
        kept = rows & pk.kept
        st = pk.measure(z1, z2)
        z, z_err = jackknife.mean(pk.counts[rows], col[rows], K)
        z_nr, z_nr_err = jackknife.mean(pk.counts_nr[kept], col[kept], K)
        # each column's share of the slab's volume [d^3] over its equal share of the slab
        vol = np.bincount(mob_col, weights=bulk.slab_volume(zm, z1, z2), minlength=K)
        phi, phi_err = jackknife.ratio(vol, np.full(K, pk.L_x * pk.L_y * (z2 - z1) / K))
        refs = rows[pk.mobile]
        xi, w = nearcontact.gaps(pk.x[pk.mobile], refs, pk.L_x, pk.L_y, hi)
        fit = nearcontact.window_stats(xi, lo, hi, w)
        out.append({"depth_lo": d_lo, "depth_hi": d_hi, "z1": z1, "z2": z2, "complete": True, "n": int(rows.sum()),
                    "z": st["z"], "z_err": z_err, "z_no_rattlers": st["z_no_rattlers"], "z_no_rattlers_err": z_nr_err,
                    "rattler_fraction": st["rattler_fraction"], "phi": st["phi"], "phi_err": phi_err,
                    "overlap_median": st["overlap_median"], "alpha": fit["alpha"], "alpha_err": fit["alpha_err"],
                    "alpha_n": fit["n"]})
    m.summary["depth_windows"] = {"columns": K, "windows": out}


def contact_fabric(m):
    """The fabric of the contact normals, plain and force-weighted, in the slab and on the depth
    windows, with jackknife errors over lateral columns (6.10)."""
    k = m.cfg.analysis.jackknife_columns
    pk, cf = m.pk, m.cf
    mid = midpoints(m)
    col = jackknife.columns(mid, pk.L_x, pk.L_y, k)
    # a tensile contact (F_n < 0: a dashpot pulling, rare in a settled pile) weighs 0 in the force fabric
    force = np.maximum(cf.F_n, 0.0)

    def of(sel):
        return {"contacts": fabric.of_contacts(cf.nrm[sel], col[sel], k * k),
                "forces": fabric.of_contacts(cf.nrm[sel], col[sel], k * k, force[sel])}

    wins = []
    for win in _windows(m):
        if win["complete"]:
            win.update(of((mid[:, 2] >= win["z1"]) & (mid[:, 2] <= win["z2"])))
        wins.append(win)
    m.summary["fabric"] = {"columns": k * k, "slab": of(m.in_slab), "windows": wins}


def free_surface(m):
    """The free surface's roughness and local slopes on cells of ``analysis.surface_cell`` (6.10)."""
    a, pk = m.cfg.analysis, m.pk
    h = surface.heights(pk.x[pk.mobile], pk.L_x, pk.L_y, a.surface_cell)
    m.summary["surface"] = dict(surface.roughness(h, pk.L_x, pk.L_y), cell=a.surface_cell,
                                incline=m.cfg.box.incline,
                                note="periodic in x and y, the mean surface is parallel to the bed: its tilt to "
                                     "gravity is box.incline")


def flow_profile(m):
    """Mean velocity, granular temperature and flux of the mobile spheres along z, and a flowing state's
    fit to the Bagnold profile (docs/model.md 5.5)."""
    if "v" not in m.arrays:
        m.summary["flow"] = None
        m.summary["flow_note"] = "no velocities in the file (a packing.npz keeps positions and contact forces)"
        return
    mob = m.pk.mobile
    v = np.asarray(m.arrays["v"], float)[mob]
    edges = m.reg["edges"]
    fp = flow.profile(m.pk.x[mob, 2], v, edges)
    m.tables["flow"] = dict(fp, edges=edges, phi=m.reg["phi_z"])
    T = fp["T"][np.isfinite(fp["T"])]
    mid = 0.5 * (edges[:-1] + edges[1:])
    v_x_mean = float(v[:, 0].mean()) if len(v) else math.nan
    flowing = v_x_mean > m.cfg.analysis.flow_v_min
    m.summary["flow"] = {"v_x_mean": v_x_mean,
                         "flux": flow.flux(v[:, 0], m.pk.L_x, m.pk.L_y),
                         "T_mean": float(np.sum((v - v.mean(axis=0)) ** 2) / (3 * len(v))) if len(v) else math.nan,
                         "T_max_bin": float(T.max()) if len(T) else math.nan,
                         # the fit of a steady chute flow's profile; None for a state at rest
                         "bagnold": flow.bagnold(mid, fp["v_x"], fp["n"], m.pk.z_bed, m.reg["h"]) if flowing else None}


@dataclass(frozen=True)
class Measure:
    """One measurement of a packing: ``run(sample)`` adds to the sample's summary and tables."""
    name: str
    run: Callable
    about: str


MEASURES = tuple(Measure(f.__name__, f, f.__doc__.split("\n")[0]) for f in (
    slab, backbone_z, backbone_cuts, isostatic_count, halved_margins, crystal_order, depth_bands,
    force_distribution, alpha, radial_distribution, force_ratios, depth_windows, contact_fabric, free_surface,
    flow_profile))


def measure(arrays, attrs, cfg):
    """All the measurements (``MEASURES``) of one state.

    Parameters
    ----------
    arrays : dict of a state sorted by id (``checkpoint.read_state``): id, x
        (n, 3), fixed (n,), and with a contact list id_i, id_j, F_n, F_t
    attrs : the file's attributes (L_x, L_y)
    cfg : Config (contact.*, analysis.*)

    Returns
    -------
    summary : dict (JSON-ready, see docs/analysis.md), with ``warnings``
    tables : dict of arrays for the CSV files and plots
    """
    m = sample(arrays, attrs, cfg)
    for row in MEASURES:
        row.run(m)
    m.summary["warnings"] = m.warnings
    return m.summary, m.tables


# -- helpers --

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


def midpoints(m):
    """(P, 3) the contacts' midpoints [d]: x_j + b / 2, b = x_i - x_j the minimum image (a contact across
    a periodic seam lies on it, possibly outside [0, L))."""
    return m.pk.x[m.pk.pairs[:, 1]] + 0.5 * m.cf.branch


def _windows(m):
    """The fixed depth windows of ``analysis.depth_windows`` below the surface h (6.10): dicts of
    depth_lo, depth_hi, z1, z2 and complete (false for a window deeper than the slab's bottom margin,
    where the bed's layering, or the bed itself, would enter; such a window is not measured)."""
    a, h = m.cfg.analysis, m.reg["h"]
    return [{"depth_lo": d_lo, "depth_hi": d_hi, "z1": h - d_hi, "z2": h - d_lo, "complete": bool(h - d_hi >= m.z1)}
            for d_lo, d_hi in zip(a.depth_windows[::2], a.depth_windows[1::2])]


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

