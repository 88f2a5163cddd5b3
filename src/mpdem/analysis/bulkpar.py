"""The bulk measurement at a run's end, each rank on its own spheres (docs/model.md 6.1-6.2).

``bulk.bulk_summary`` measures a whole pile held by one process; a run on many ranks would have to
gather every sphere's position on one of them first. Here each rank measures the spheres it owns,
with their contacts to its ghost rows (the halo reaches past a contact), and what the measures add
over spheres or contacts is added exactly: counts as integers, doubles as fixed-point limbs
(``kernels.exactsum``) summed over the ranks. The rattler rules remove spheres in rounds, every
rank's removals of a round passed to the ranks that hold them as ghosts before the next; a sphere's
contacts enter the force rule's balance in the order of their partners' ids; the median overlap is
found by its bits, a byte at a time. So every rank count and grid gives the same bits, and no rank
holds more than its rows and ghosts. Against ``bulk_summary`` of the same pile the numbers agree to
round-off (its sums run in row order).

The ranks are reached through a ``net``: ``sum_int``, ``max_many`` (``decomp.Domain``'s exact
reductions) and ``to_ghosts`` (a (rows, 3) float array's owned rows copied into its ghost rows);
``ALONE`` is the one-process net.
"""
from __future__ import annotations

import math

import numpy as np
from ..kernels.exactsum import bin_limbs, to_float
from ..kernels.pairdist import close_pairs, separations
from ..kernels.particle import R
from . import backbone as bb
from .bulk import NO_BACKBONE, NoBulk, packing_fraction, phi_profile, region_of_profile
from .contacts import band_index, elastic_normal, n_bands


class _Alone:
    """The net of one process: every reduction is the value itself, no ghosts."""

    @staticmethod
    def sum_int(arr):
        return np.asarray(arr, np.int64)

    @staticmethod
    def max_many(values):
        return np.fmin(np.asarray(values, float), np.inf)

    @staticmethod
    def to_ghosts(field):
        return None


ALONE = _Alone()


def _sums(net, bins, values, n_bins):
    """(n_bins,) float64: the exact sums over every rank of ``values`` by ``bins``, each rounded once.

    The limbs travel for the bins some rank fills only (a count a bin first): a sphere flown far above
    the pile leaves thousands of empty bins between."""
    bins = np.asarray(bins, np.int64)
    filled = np.flatnonzero(_counts(net, bins, n_bins))
    slot = np.full(n_bins, -1, np.int64)
    slot[filled] = np.arange(len(filled))
    acc = net.sum_int(bin_limbs(slot[bins], np.asarray(values, np.float64), len(filled)))
    out = np.zeros(n_bins)
    for k, b in enumerate(filled):
        out[b] = to_float(acc[k])
    return out


def _counts(net, values, n):
    """(n,) int64: bincount of ``values`` summed over every rank."""
    return np.array(net.sum_int(np.bincount(np.asarray(values, np.int64), minlength=n)[:n]))


SIGN = np.uint64(1 << 63)


def _kth(net, values, k):
    """The k-th smallest (0-based) of the doubles ``values`` of every rank (no NaN), by their bits."""
    raw = np.ascontiguousarray(values, np.float64).view(np.uint64)
    # keys in the order of the values: a positive's bits with the sign bit set, a negative's bits inverted
    bits = np.where(raw & SIGN, ~raw, raw | SIGN)
    prefix, mask = 0, 0
    for shift in range(56, -8, -8):            # a byte at a time, the most significant first
        mine = bits[(bits & np.uint64(mask)) == np.uint64(prefix)]
        hist = _counts(net, ((mine >> np.uint64(shift)) & np.uint64(0xFF)).astype(np.int64), 256)
        below = np.cumsum(hist)
        byte = int(np.searchsorted(below, k, side="right"))
        k -= int(below[byte - 1]) if byte else 0
        prefix |= byte << shift
        mask |= 0xFF << shift
    key = np.uint64(prefix)
    return float(np.array([key & ~SIGN if key & SIGN else ~key], np.uint64).view(np.float64)[0])


def _median(net, values):
    """np.median of the values of every rank (0.0 where there are none)."""
    n = int(net.sum_int(np.array([len(values)]))[0])
    if n == 0:
        return 0.0
    if n % 2:
        return _kth(net, values, n // 2)
    return float(np.mean([_kth(net, values, n // 2 - 1), _kth(net, values, n // 2)]))


def _by_sphere(pairs, ids, rows):
    """Each row's contacts, (contact, +1 if the row is the pair's first end else -1), their partners' ids
    ascending: (order (2M,), start (rows + 1,), sign (2M,), which (2M,))."""
    M = len(pairs)
    ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
    other = np.concatenate([pairs[:, 1], pairs[:, 0]])
    which = np.concatenate([np.arange(M), np.arange(M)])
    sign = np.concatenate([np.ones(M), -np.ones(M)])
    order = np.lexsort((ids[other], ends))
    start = np.searchsorted(ends[order], np.arange(rows + 1))
    return order, start, sign, which


def _rounds(net, kept, n_own, drop_of, pairs):
    """Remove spheres in rounds until none goes: ``drop_of(kept, todo)`` names the owned rows of ``todo``
    to remove given ``kept``; each round's removals reach the ghosts; ``kept`` (rows,) bool, in place."""
    todo = np.flatnonzero(kept[:n_own])
    flags = np.zeros((len(kept), 3))
    while True:
        drop = drop_of(kept, todo)
        if int(net.sum_int(np.array([len(drop)]))[0]) == 0:
            return kept
        before = kept.copy()
        kept[drop] = False
        flags[:, 0] = kept
        net.to_ghosts(flags)
        kept[n_own:] = flags[n_own:, 0] > 0.5
        gone = np.flatnonzero(before & ~kept)
        hit = np.isin(pairs, gone)
        near = np.unique(np.concatenate([pairs[hit[:, 1], 0], pairs[hit[:, 0], 1]]))
        todo = near[(near < n_own) & kept[near]]


def measure(x, fixed, ids, n_own, L_x, L_y, mu, net=ALONE, margin_bottom=-1.0, margin_top=-1.0, n_min=-1,
            profile_bin=0.5, tall_pile=40.0, rattlers="count", k_n=2e5, model="hooke", force_fraction=0.01,
            band_width=2.5, planes=()):
    """``bulk.bulk_summary`` of a pile spread over ranks (a collective: every rank calls it alike).

    Parameters
    ----------
    x : (rows, 3) positions [d]: the rank's owned rows, then its ghost rows (exact copies of their
        owners', coordinates in [0, L) in x and y)
    fixed : (rows,) 1 for bed spheres; ids : (rows,) int64 particle ids
    n_own : the owned rows (the first ones)
    net : the ranks (``ALONE`` on one process; module docstring)
    the rest : as ``bulk.bulk_summary``

    Returns
    -------
    dict, on every rank: the keys of ``bulk.bulk_summary``, the same bits for any ranks and grid.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    ids = np.asarray(ids, np.int64)
    fixed = np.asarray(fixed).astype(bool)
    rows = len(x)
    own = np.arange(rows) < n_own
    mobile = ~fixed
    zo, mo = x[:n_own, 2], mobile[:n_own]
    n_mobile = int(net.sum_int(np.array([np.count_nonzero(mo)]))[0])
    if n_mobile == 0:
        raise NoBulk("no mobile particles to analyse")
    inf = math.inf
    bed_top, top, neg_low = net.max_many([zo[~mo].max() if (~mo).any() else -inf,
                                          zo[mo].max() if mo.any() else -inf,
                                          -zo[mo].min() if mo.any() else -inf])
    z_bed = float(bed_top) if bed_top > -inf else float(-neg_low) - R
    def sums(bins, values, n_bins):
        return _sums(net, bins, values, n_bins)

    edges, phi_z = phi_profile(zo[mo], L_x, L_y, z_bed, float(top) + 1.0, profile_bin, sums)
    reg = region_of_profile(edges, phi_z, float(top) + 1.0, n_mobile, z_bed, L_x, L_y, margin_bottom,
                            margin_top, tall_pile)

    # contacts: every pair with an owned sphere, the lower id first; bed-bed overlaps are no contacts
    pairs = close_pairs(x, L_x, L_y, 1.0)
    pairs = pairs[(own[pairs[:, 0]] | own[pairs[:, 1]]) & ~(fixed[pairs[:, 0]] & fixed[pairs[:, 1]])]
    flip = ids[pairs[:, 0]] > ids[pairs[:, 1]]
    pairs[flip] = pairs[flip][:, ::-1]
    branch = separations(x, pairs[:, 0], pairs[:, 1], L_x, L_y)
    r = np.sqrt(np.einsum("ij,ij->i", branch, branch))
    mine = own[pairs[:, 0]]                    # a pair counted once over the ranks: by its first end's owner
    counts = np.bincount(pairs.ravel(), minlength=rows)
    n_min = (4 if mu == 0 else 2) if n_min < 0 else int(n_min)

    def count_rule(kept, todo):
        live = kept[pairs[:, 0]] & kept[pairs[:, 1]]
        c = np.bincount(pairs[live].ravel(), minlength=rows)
        return todo[mobile[todo] & (c[todo] < n_min)]

    kept_count = _rounds(net, np.ones(rows, bool), n_own, count_rule, pairs)
    live = kept_count[pairs[:, 0]] & kept_count[pairs[:, 1]]
    counts_count = np.bincount(pairs[live].ravel(), minlength=rows)
    rule, kept, counts_nr = "count", kept_count, counts_count
    if rattlers == "force":
        kept, counts_nr = _backbone(net, x, mobile, ids, n_own, pairs, branch, r, mine, reg["h"], z_bed, mu,
                                    k_n, model, force_fraction, band_width, planes)
        rule = "force"

    out = {k: v for k, v in reg.items() if k not in ("edges", "phi_z")}
    out["n_min"] = n_min
    z1, z2 = reg["z1"], reg["z2"]
    bulk = mobile & (x[:, 2] >= z1) & (x[:, 2] <= z2)
    out.update(_coordination(net, counts, kept, counts_nr, bulk & own))
    out["rattlers"] = rule
    if rule != "count":
        c = _coordination(net, counts, kept_count, counts_count, bulk & own)
        out["count_rule"] = {"n_min": n_min, "z_no_rattlers": c["z_no_rattlers"],
                             "rattler_fraction": c["rattler_fraction"]}
        if out["n_bulk"] and not _any_kept(net, kept, bulk & own):
            out["rattler_note"] = NO_BACKBONE
    out["phi"] = packing_fraction(zo[mo], L_x, L_y, z1, z2, sums)
    overl = 1.0 - r[mine & (bulk[pairs[:, 0]] | bulk[pairs[:, 1]])]
    out["overlap_median"] = _median(net, overl)
    top_overlap = float(net.max_many([overl.max() if overl.size else -inf])[0])
    out["overlap_max"] = top_overlap if top_overlap > -inf else 0.0
    return out


def _any_kept(net, kept, bulk):
    """Whether any rank keeps a sphere of the bulk."""
    return int(net.sum_int(np.array([np.count_nonzero(kept & bulk)]))[0]) > 0


def _coordination(net, counts, kept, counts_nr, bulk):
    """``bulk.coordination`` over the owned bulk spheres of every rank (integer sums)."""
    bk = bulk & kept
    top = 12
    h = _counts(net, np.minimum(counts[bulk], top), top + 1)
    h_nr = _counts(net, np.minimum(counts_nr[bk], top), top + 1)
    s = net.sum_int(np.array([counts[bulk].sum(), counts_nr[bk].sum(), np.count_nonzero(bulk),
                              np.count_nonzero(bk)], np.int64))
    total, total_nr, nb, nbk = (int(v) for v in s)
    return {
        "z": total / nb if nb else math.nan,
        "z_no_rattlers": total_nr / nbk if nbk else math.nan,
        "rattler_fraction": float(1.0 - nbk / nb) if nb else math.nan,
        "n_bulk": nb,
        "P_z": (h / max(h.sum(), 1)).tolist(),
        "P_z_no_rattlers": (h_nr / max(h_nr.sum(), 1)).tolist(),
    }


def _backbone(net, x, mobile, ids, n_own, pairs, branch, r, mine, h, z_bed, mu, k_n, model, force_fraction,
              band_width, planes):
    """``backbone.of_packing`` over the ranks: (kept (rows,), counts (rows,)) for the owned rows."""
    rows = len(x)
    nrm = branch / r[:, None]
    F_n = elastic_normal(1.0 - r, k_n, model)
    B = n_bands(h, z_bed, band_width)
    band = band_index(0.5 * (x[pairs[:, 0], 2] + x[pairs[:, 1], 2]), h, band_width, B)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = _sums(net, band[mine], F_n[mine], B) / _counts(net, band[mine], B)
    weak = ~(F_n >= force_fraction * means[band])
    # the supports of the owned spheres: their contacts with the planes, cut alike
    s_rows, s_nrm = [], []
    mob = np.flatnonzero(mobile[:n_own])
    for p in planes:
        n = np.asarray(p.normal)
        d = R - (x[mob] @ n - p.offset)
        on = d > 0.0
        ref = np.nan_to_num(means[band_index(x[mob[on], 2], h, band_width, B)], nan=0.0)
        strong = elastic_normal(d[on], k_n, model) >= force_fraction * ref
        s_rows.append(mob[on][strong])
        s_nrm.append(np.broadcast_to(n, (int(strong.sum()), 3)))
    s_rows = np.concatenate(s_rows).astype(np.int64) if s_rows else np.zeros(0, np.int64)
    s_nrm = np.concatenate(s_nrm) if len(s_rows) else np.zeros((0, 3))
    by = np.argsort(s_rows, kind="stable")
    s_rows, s_nrm = s_rows[by], s_nrm[by]
    s_start = np.searchsorted(s_rows, np.arange(rows + 1))
    order, start, sign, which = _by_sphere(pairs, ids, rows)

    def unbalanced(kept, todo):
        live = ~weak & kept[pairs[:, 0]] & kept[pairs[:, 1]]
        drop = []
        for s in todo:
            if not mobile[s]:
                continue
            u = bb.directions(s, order, start, sign, which, live, nrm, s_start, s_nrm)
            if not bb.balances_weight(u, mu):
                drop.append(s)
        return np.asarray(drop, np.int64)

    kept = _rounds(net, np.ones(rows, bool), n_own, unbalanced, pairs)
    live = ~weak & kept[pairs[:, 0]] & kept[pairs[:, 1]]
    return kept, np.bincount(pairs[live].ravel(), minlength=rows)
