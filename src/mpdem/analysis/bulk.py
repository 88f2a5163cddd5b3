"""Bulk region, contacts, coordination and packing fraction (docs/model.md 6.1-6.3).

Every run reports these at its end (``bulk_summary``); ``mpdem analyze``
builds the rest of section 6 on them.
"""
from __future__ import annotations

import math

import numpy as np

from ..kernels.exactsum import bin_sums
from ..kernels.pairdist import close_pairs, separations
from ..kernels.particle import R


class NoBulk(ValueError):
    """The pile has no bulk to measure (no mobile sphere, or too short for its margins): decided by
    numbers every rank of a run holds alike."""


def slab_volume(zc, a, b, radius=R):
    """Volume of spheres of centre height zc inside the slab a <= z <= b [d^3].

    Parameters
    ----------
    zc : array of float
    a, b : float or arrays broadcastable with zc

    V = pi [R^2 u - u^3 / 3] between u = clamp(a - zc) and clamp(b - zc), with
    clamp to [-R, R] (the exact sphere-slab intersection).
    """
    ua = np.clip(a - zc, -radius, radius)
    ub = np.clip(b - zc, -radius, radius)
    return math.pi * ((radius ** 2 * ub - ub ** 3 / 3) - (radius ** 2 * ua - ua ** 3 / 3))


def phi_profile(z, L_x, L_y, z0, z1, width=0.5, sums=bin_sums):
    """Horizontally averaged packing fraction phi(z) of spheres at heights z.

    Returns
    -------
    edges : (nb + 1,) bin edges [d] from z0 to at least z1
    phi : (nb,) packing fraction per bin (exact sphere-slab volumes)

    ``sums(bins, values, nb)``: the bins' exact sums (``exactsum.bin_sums``; over ranks: ``bulkpar``).
    """
    nb = max(1, int(math.ceil((z1 - z0) / width)))
    edges = z0 + width * np.arange(nb + 1)
    base = np.floor((z - z0) / width).astype(np.int64)
    reach = int(math.ceil(R / width))
    bins, vols = [], []
    for k in range(-reach, reach + 1):
        b = base + k
        ok = (b >= 0) & (b < nb)
        bins.append(b[ok])
        vols.append(slab_volume(z[ok], edges[b[ok]], edges[b[ok] + 1]))
    # exact sums, as the ranks of a run make them at its end (``bulkpar``): the same bits in any order
    vol = sums(np.concatenate(bins), np.concatenate(vols), nb)
    return edges, vol / (L_x * L_y * width)


def find_contacts(x, L_x, L_y):
    """All overlapping pairs (r < d, strict) with minimum image in x and y.

    Parameters
    ----------
    x : (n, 3) positions [d]

    Returns
    -------
    pairs : (M, 2) int64 row indices, i < j
    r : (M,) centre distances [d]
    """
    pairs = close_pairs(x, L_x, L_y, 1.0)
    d = separations(np.asarray(x, dtype=np.float64), pairs[:, 0], pairs[:, 1], L_x, L_y)
    return pairs, np.sqrt(np.einsum("ij,ij->i", d, d))


def remove_rattlers(n_rows, pairs, removable, n_min):
    """Iteratively remove particles with fewer than n_min contacts.

    Parameters
    ----------
    n_rows : int
    pairs : (M, 2) int contacts
    removable : (n_rows,) bool, False for particles never removed (the bed)
    n_min : int

    Returns
    -------
    kept : (n_rows,) bool
    counts : (n_rows,) int contacts among kept particles
    """
    kept = np.ones(n_rows, bool)
    while True:
        live = kept[pairs[:, 0]] & kept[pairs[:, 1]]
        counts = np.bincount(pairs[live].ravel(), minlength=n_rows)
        drop = kept & removable & (counts < n_min)
        if not drop.any():
            return kept, counts
        kept &= ~drop


def bulk_region(zm, z_bed, L_x, L_y, margin_bottom=-1.0, margin_top=-1.0, profile_bin=0.5, tall_pile=40.0):
    """The bulk slab [z1, z2] of a pile (docs/model.md 6.1).

    Parameters
    ----------
    zm : (n_mobile,) centre heights of the mobile spheres [d]
    z_bed : float top of the bed (highest bed centre) [d]
    margin_bottom, margin_top : float bulk margins [d]; -1 = automatic: 10 d
        for a pile at least ``tall_pile`` high (h - z_bed, the paper's ~45 d),
        else clamp(0.2 (h - z_bed), 3, 10)
    profile_bin : float bin width of phi(z) [d]

    Returns
    -------
    dict with z1, z2, h, z_bed, margin_bottom, margin_top, phi_plateau, the
    plateau window ``plateau_lo``, ``plateau_hi`` [d] and the profile
    (``edges`` (nb + 1,), ``phi_z`` (nb,) arrays).
    """
    top = float(zm.max()) + 1.0
    edges, phi = phi_profile(zm, L_x, L_y, z_bed, top, profile_bin)
    return region_of_profile(edges, phi, top, zm.size, z_bed, L_x, L_y, margin_bottom, margin_top, tall_pile)


def region_of_profile(edges, phi, top, n_mobile, z_bed, L_x, L_y, margin_bottom=-1.0, margin_top=-1.0,
                      tall_pile=40.0):
    """``bulk_region`` from the pile's profile ``phi`` (nb,) on ``edges`` (nb + 1,) [d], its highest
    centre plus one ``top`` [d] and its count of mobile spheres (``phi_profile``, made elsewhere)."""
    centres = 0.5 * (edges[:-1] + edges[1:])
    # plateau window of docs/model.md 6.1, shrunk for piles shorter than the paper's
    h_nominal = n_mobile * math.pi / 6 / (L_x * L_y * 0.6)
    lo, hi = z_bed + min(10.0, 0.25 * h_nominal), z_bed + min(30.0, 0.75 * h_nominal)
    win = (centres >= lo) & (centres <= hi)
    plateau = float(np.median(phi[win])) if win.any() else float(phi.max())
    above = np.flatnonzero(phi >= 0.5 * plateau)
    h = float(centres[above[-1]]) if above.size else top
    auto = 10.0 if h - z_bed >= tall_pile else min(max(0.2 * (h - z_bed), 3.0), 10.0)
    mb = auto if margin_bottom < 0 else margin_bottom
    mt = mb if margin_top < 0 else margin_top
    z1, z2 = z_bed + mb, h - mt
    if not z2 > z1:
        raise NoBulk(f"pile too short for a bulk region: z_bed = {z_bed:.3g}, h = {h:.3g}, "
                         f"margins {mb:.3g} and {mt:.3g}")
    return {"z1": z1, "z2": z2, "h": h, "z_bed": z_bed, "margin_bottom": mb, "margin_top": mt,
            "phi_plateau": plateau, "plateau_lo": lo, "plateau_hi": hi, "edges": edges, "phi_z": phi}


def packing_fraction(zm, L_x, L_y, z1, z2, sums=bin_sums):
    """phi_f: volume of all mobile spheres inside the slab [z1, z2] over its volume (6.3); ``sums`` as
    ``phi_profile``'s."""
    vol = sums(np.zeros(len(zm), np.int64), slab_volume(zm, z1, z2), 1)[0]
    return float(vol / (L_x * L_y * (z2 - z1)))


def histogram_z(counts, top=12):
    """P(n) for n = 0 .. top, the last bin holding n >= top; sums to 1."""
    h = np.bincount(np.minimum(counts, top), minlength=top + 1).astype(float)
    return h / max(h.sum(), 1.0)


def coordination(counts, kept, counts_nr, bulk):
    """z, z without rattlers, rattler fraction and P(z) of the bulk particles (6.2).

    Parameters
    ----------
    counts : (n,) contacts of every particle
    kept : (n,) bool, False for rattlers; counts_nr : (n,) contacts among kept
    bulk : (n,) bool bulk particles
    """
    nb = int(bulk.sum())
    bk = bulk & kept
    return {
        "z": float(counts[bulk].mean()) if nb else math.nan,
        "z_no_rattlers": float(counts_nr[bk].mean()) if bk.any() else math.nan,
        "rattler_fraction": float(1.0 - bk.sum() / nb) if nb else math.nan,
        "n_bulk": nb,
        "P_z": histogram_z(counts[bulk]).tolist(),
        "P_z_no_rattlers": histogram_z(counts_nr[bk]).tolist(),
    }


# what the summaries say instead of "100 % rattlers" when the force rule keeps no sphere of the bulk
NO_BACKBONE = ("not measured: no sphere of the bulk holds its weight on the contacts the force rule sees (a "
               "support it does not see, such as a plane other than bed.wall, or forces of another state)")


def rattlers_text(s):
    """'z_nr (f % rattlers)' of a bulk summary ``s`` (``Packing.measure``), or why the rule could not say."""
    if s.get("rattler_note"):
        return s["rattler_note"]
    return f"{s['z_no_rattlers']:.3f} ({100 * s['rattler_fraction']:.1f}% rattlers)"


class Packing:
    """A static packing with its contacts, ready for the bulk measurements.

    Parameters
    ----------
    x : (n, 3) positions [d]; fixed : (n,) 1 for bed spheres
    L_x, L_y : box [d]; mu : friction (sets the default rattler threshold)
    n_min : threshold of the count rule; -1 = 4 for mu = 0, 2 for mu > 0
    planes : sequence of ``planes.Plane``
        Flat boundaries the pile rests on besides its bed (``planes.of_config``: the wall under the
        bed); their contacts support the backbone's spheres (``plane_contacts``).

    Contacts (``pairs``, ``r``): every overlapping pair with a mobile sphere in it;
    two bed spheres overlap where the bed froze, but they never interact.

    Rattlers: built with the count rule (``remove_rattlers``, ``kept_count``,
    ``counts_count``); ``use_backbone`` switches ``kept`` and ``counts_nr`` to
    the force-based backbone (docs/model.md 6.2), the default of the analysis.
    """

    def __init__(self, x, fixed, L_x, L_y, mu, n_min=-1, planes=()):
        self.x = np.ascontiguousarray(x, dtype=np.float64)
        self.planes = tuple(planes)
        self.fixed = np.asarray(fixed).astype(bool)
        self.mobile = ~self.fixed
        if not self.mobile.any():
            raise NoBulk("no mobile particles to analyse")
        self.L_x, self.L_y, self.mu = float(L_x), float(L_y), float(mu)
        zm = self.x[self.mobile, 2]
        self.z_bed = float(self.x[self.fixed, 2].max()) if self.fixed.any() else float(zm.min()) - R
        pairs, r = find_contacts(self.x, self.L_x, self.L_y)
        # bed-bed pairs are never computed (docs/model.md 2.8): the bed's own overlaps are no contacts
        real = ~(self.fixed[pairs[:, 0]] & self.fixed[pairs[:, 1]])
        self.pairs, self.r = pairs[real], r[real]
        n = len(self.x)
        self.counts = np.bincount(self.pairs.ravel(), minlength=n)
        self.n_min = (4 if mu == 0 else 2) if n_min < 0 else int(n_min)
        self.kept_count, self.counts_count = remove_rattlers(n, self.pairs, self.mobile, self.n_min)
        self.rule = "count"
        self.kept, self.counts_nr = self.kept_count, self.counts_count

    def plane_contacts(self):
        """The mobile spheres' contacts with ``planes``: rows (A,) int64, unit normals into the
        sphere (A, 3) (the plane's), overlaps (A,) [d]."""
        rows, nrm, delta = [], [], []
        mob = np.flatnonzero(self.mobile)
        for p in self.planes:
            n = np.asarray(p.normal)
            d = R - (self.x[mob] @ n - p.offset)
            on = d > 0.0
            rows.append(mob[on])
            nrm.append(np.broadcast_to(n, (int(on.sum()), 3)))
            delta.append(d[on])
        if not rows:
            return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0)
        return np.concatenate(rows).astype(np.int64), np.concatenate(nrm), np.concatenate(delta)

    def use_backbone(self, kept, counts):
        """Rattlers from now on by the force-based backbone (``backbone.of_packing``)."""
        self.rule, self.kept, self.counts_nr = "force", kept, counts

    def in_slab(self, z1, z2):
        """(n,) bool: mobile particles with centres in [z1, z2]."""
        return self.mobile & (self.x[:, 2] >= z1) & (self.x[:, 2] <= z2)

    def measure(self, z1, z2):
        """z, z_nr, rattler fraction, P(z), phi_f and bulk overlaps for the slab [z1, z2].

        z_no_rattlers and rattler_fraction follow the packing's rule (``rattlers``);
        ``count_rule`` holds the count rule's when the backbone is in use.
        """
        bulk = self.in_slab(z1, z2)
        out = coordination(self.counts, self.kept, self.counts_nr, bulk)
        out["rattlers"] = self.rule
        if self.rule != "count":
            c = coordination(self.counts, self.kept_count, self.counts_count, bulk)
            out["count_rule"] = {"n_min": self.n_min, "z_no_rattlers": c["z_no_rattlers"],
                                 "rattler_fraction": c["rattler_fraction"]}
            if bulk.any() and not (self.kept & bulk).any():
                out["rattler_note"] = NO_BACKBONE
        out["phi"] = packing_fraction(self.x[self.mobile, 2], self.L_x, self.L_y, z1, z2)
        in_bulk = bulk[self.pairs[:, 0]] | bulk[self.pairs[:, 1]]
        overl = 1.0 - self.r[in_bulk]
        out["overlap_median"] = float(np.median(overl)) if overl.size else 0.0
        out["overlap_max"] = float(overl.max()) if overl.size else 0.0
        return out

    def region(self, margin_bottom=-1.0, margin_top=-1.0, profile_bin=0.5, tall_pile=40.0):
        """``bulk_region`` of this packing."""
        return bulk_region(self.x[self.mobile, 2], self.z_bed, self.L_x, self.L_y,
                           margin_bottom, margin_top, profile_bin, tall_pile)


def bulk_summary(x, fixed, L_x, L_y, mu, margin_bottom=-1.0, margin_top=-1.0, n_min=-1,
                 profile_bin=0.5, tall_pile=40.0, packing=None, rattlers="count", k_n=2e5, model="hooke",
                 force_fraction=0.01, band_width=2.5, planes=()):
    """Bulk z, z without rattlers, rattler fraction and phi_f of a packing.

    Parameters
    ----------
    x : (n, 3) positions [d]; fixed : (n,) 1 for bed spheres
    mu : friction (sets the default rattler threshold)
    margin_bottom, margin_top : bulk margins [d]; -1 = automatic (6.1)
    n_min : threshold of the count rule; -1 = 4 for mu = 0, 2 for mu > 0
    packing : Packing of the same arguments, if already built
    rattlers : 'force' (the backbone, with the elastic normal forces of the overlaps:
        k_n, model, force_fraction, band_width) or 'count' (n_min)
    planes : the planes the pile rests on besides its bed (``Packing``)

    Returns
    -------
    dict with z, z_no_rattlers, rattler_fraction, phi, n_bulk, z1, z2, h,
    z_bed, margins, n_min, phi_plateau, P(z) with and without rattlers,
    median and maximum bulk overlap, the rule ``rattlers``.
    """
    pk = packing or Packing(x, fixed, L_x, L_y, mu, n_min, planes)
    reg = pk.region(margin_bottom, margin_top, profile_bin, tall_pile)
    if rattlers == "force":
        from . import backbone, contacts
        cf = contacts.contact_forces(pk, {}, k_n, mu, model)
        bb = backbone.of_packing(pk, cf, reg["h"], band_width, force_fraction)
        pk.use_backbone(bb["kept"], bb["counts"])
    out = {k: v for k, v in reg.items() if k not in ("edges", "phi_z")}
    out["n_min"] = pk.n_min
    out.update(pk.measure(reg["z1"], reg["z2"]))
    return out
