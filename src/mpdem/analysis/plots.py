"""PNG plots of one analysis (``mpdem analyze``); matplotlib without a display."""
from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors  # noqa: E402
import matplotlib.patches  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io.rundir import atomic  # noqa: E402


FORMATS = ("png", "pdf", "svg")


def formats_of(text):
    """``analysis.figure_format`` ('png', 'png,pdf', ...) as a tuple of formats (config checks each)."""
    return tuple(dict.fromkeys(f.strip().lower() for f in str(text).split(",") if f.strip()))


def save(fig, path, formats=("png",)):
    """Write a figure in each of ``formats`` (``path`` with its suffix swapped), each under a
    temporary name, then renamed. PNG at 120 dpi; PDF and SVG are vector."""
    stem = os.path.splitext(path)[0]
    for fmt in formats:
        with atomic(f"{stem}.{fmt}", "wb") as fh:
            fig.savefig(fh, format=fmt, dpi=120, bbox_inches="tight")
    plt.close(fig)


def _slab(ax, s, vertical=False):
    span = ax.axvspan if vertical else ax.axhspan
    span(s["z1"], s["z2"], color="tab:green", alpha=0.12, label=f"bulk [{s['z1']:.1f}, {s['z2']:.1f}]")


def plot_profile(out, s, t, formats=("png",)):
    """phi(z) and z(z) with the bulk slab, surface and phi_f."""
    reg = t["profile"]
    zc = 0.5 * (reg["edges"][:-1] + reg["edges"][1:])
    _, z_all, z_nr = t["z_profile"]
    fig, (a, b) = plt.subplots(1, 2, figsize=(8, 4.5), sharey=True)
    a.plot(reg["phi_z"], zc, "k-", lw=1)
    _slab(a, s)
    a.axhline(s["h"], color="tab:red", ls="--", lw=0.8, label=f"surface h = {s['h']:.1f}")
    a.plot([s["phi"]] * 2, [s["z1"], s["z2"]], color="tab:blue", lw=2, label=f"$\\phi_f$ = {s['phi']:.4f}")
    a.set(xlabel="$\\phi(z)$", ylabel="z [d]", title="packing fraction")
    a.legend(fontsize=8, loc="lower left")
    b.plot(z_all, zc, "k.-", ms=3, lw=0.8, label=f"all (bulk z = {s['z']:.3f})")
    b.plot(z_nr, zc, ".-", color="tab:orange", ms=3, lw=0.8,
           label=f"no rattlers (bulk {s['z_no_rattlers']:.3f})")
    _slab(b, s)
    b.set(xlabel="contacts per sphere", title="coordination")
    b.legend(fontsize=8, loc="lower left")
    save(fig, os.path.join(out, "profile.png"), formats)


def plot_coordination(out, s, formats=("png",)):
    """P(z) of the bulk, with and without rattlers."""
    n = np.arange(len(s["P_z"]))
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.bar(n - 0.2, s["P_z"], 0.4, label=f"all, z = {s['z']:.3f}")
    ax.bar(n + 0.2, s["P_z_no_rattlers"], 0.4, label=f"no rattlers, z = {s['z_no_rattlers']:.3f}")
    ax.set(xlabel="contacts n (last bin: n >= 12)", ylabel="P(n)", xticks=n)
    ax.legend(fontsize=8)
    save(fig, os.path.join(out, "coordination.png"), formats)


def plot_gofr(out, s, t, formats=("png",)):
    """g(r) on linear bins, and the near-contact g against xi with the eq. 6 fit."""
    g = t["gofr"]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(0.5 * (g["r_lo"] + g["r_hi"]), g["g"], "k-", lw=0.7)
    ax.axhline(1.0, color="grey", lw=0.5)
    ax.set(xlabel="r / d", ylabel="g(r)", xlim=(0.8, g["r_max"]),
           title=f"bulk g(r): {g['n_ref']} reference spheres")
    save(fig, os.path.join(out, "gofr.png"), formats)

    nr, xi, fit = t["near"], t["xi_c"], t["fit"]
    ok = nr["g_xi"] > 0
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.loglog(xi[ok], nr["g_xi"][ok], "ko", ms=3, label="g(r), r > d")
    ax.axvspan(fit["xi_lo"], fit["xi_hi"], color="tab:green", alpha=0.12, label="window")
    if np.isfinite(fit["alpha"]):
        from .nearcontact import prefactor
        xs = np.array([fit["xi_lo"], fit["xi_hi"]])
        C = prefactor(fit, fit["n_ref"], nr["rho"])
        ax.loglog(xs, C * xs ** -fit["alpha"], "r-",
                  label=f"$\\alpha$ = {fit['alpha']:.3f} $\\pm$ {fit['alpha_err']:.3f} (max. likelihood)")
    ax.set(xlabel="$\\xi = r/d - 1$", ylabel="g", title="near contact (eq. 6)")
    ax.legend(fontsize=8)
    save(fig, os.path.join(out, "gofr_near.png"), formats)


def plot_zeta(out, s, t, formats=("png",)):
    """P(zeta) normalised by its largest bin (and F_t/F_n for mu >= 1)."""
    z = t["zeta"]
    c = 0.5 * (z["edges"][:-1] + z["edges"][1:])
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(c, z["P_zeta"], "k.-", label=f"$\\zeta = F_t/\\mu F_n$ ({z['n_contacts']} contacts)")
    if "P_ratio" in z:
        ax.plot(c, z["P_ratio"], ".-", color="tab:blue", label="$F_t/F_n$")
    ax.set(xlabel="$\\zeta$", ylabel="P / max P", ylim=(0, 1.05),
           title=f"{100 * z['mobilised_fraction']:.1f}% fully mobilised")
    ax.legend(fontsize=8)
    save(fig, os.path.join(out, "zeta.png"), formats)


def _spheres(ax, xy, colours, edge="none"):
    """Discs of diameter 1 at the centres xy (n, 2), in data units."""
    from matplotlib.collections import EllipseCollection
    n = len(xy)
    ax.add_collection(EllipseCollection(np.ones(n), np.ones(n), np.zeros(n), units="xy", offsets=xy,
                                        offset_transform=ax.transData, facecolors=colours, edgecolors=edge,
                                        linewidths=0.2))


def plot_packing(out, s, t, slab=2.0, formats=("png",)):
    """A picture of the packing: a side view of a slab coloured by contact number, the bulk marked,
    and a top view of the bed coloured by height.

    Parameters
    ----------
    slab : float
        Thickness in y of the side view's slab, about the middle of the box [d].
    """
    pk = t["packing"]
    x, fixed, counts, L_x, L_y = pk["x"], pk["fixed"], pk["counts"], pk["L_x"], pk["L_y"]
    mid = 0.5 * L_y
    # the slab |y - L_y / 2| < slab / 2, drawn back to front so nearer spheres cover farther ones
    sel = np.flatnonzero(np.abs(x[:, 1] - mid) < 0.5 * slab)
    sel = sel[np.argsort(-(x[sel, 1] - mid))]
    top = float(x[:, 2].max()) + 1.0 if len(x) else 1.0
    width = 8.0 + 4.0 * L_y / max(L_x, 1.0)
    fig, (a, b) = plt.subplots(1, 2, figsize=(width, 6), gridspec_kw={"width_ratios": [2, 1]})
    cmap = plt.get_cmap("viridis", 13)
    colours = np.where(fixed[sel, None], np.array([[0.6, 0.6, 0.6, 1.0]]), cmap(np.minimum(counts[sel], 12)))
    _spheres(a, x[sel][:, [0, 2]], colours, edge="k")
    a.axhspan(s["z1"], s["z2"], color="tab:red", alpha=0.10, zorder=0)
    for z in (s["z1"], s["z2"]):
        a.axhline(z, color="tab:red", lw=0.8, ls="--")
    a.text(0.0, s["z2"] + 0.1, f"bulk z in [{s['z1']:.1f}, {s['z2']:.1f}]", color="tab:red", va="bottom",
           fontsize=9, bbox=dict(facecolor="white", alpha=0.8, edgecolor="none", pad=1))
    a.set(xlim=(-0.5, L_x + 0.5), ylim=(min(-0.5, float(x[:, 2].min()) - 0.6) if len(x) else -0.5, top),
          aspect="equal", xlabel="x [d]", ylabel="z [d]",
          title=f"side view: |y - {mid:g}| < {0.5 * slab:g} d, {len(sel)} spheres (grey: bed)")
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=matplotlib.colors.Normalize(-0.5, 12.5))
    fig.colorbar(sm, ax=a, ticks=range(0, 13, 2), label="contacts (12: 12 or more)", shrink=0.7)
    bed = np.flatnonzero(fixed)
    if len(bed):
        zb = x[bed, 2]
        norm = matplotlib.colors.Normalize(float(zb.min()), float(zb.max()) + 1e-12)
        _spheres(b, x[bed][:, :2], plt.get_cmap("cividis")(norm(zb)), edge="k")
        fig.colorbar(plt.cm.ScalarMappable(cmap="cividis", norm=norm), ax=b, label="bed sphere height z [d]",
                     shrink=0.7)
    b.add_patch(matplotlib.patches.Rectangle((0, 0), L_x, L_y, fill=False, lw=0.8))
    b.set(xlim=(-0.5, L_x + 0.5), ylim=(-0.5, L_y + 0.5), aspect="equal", xlabel="x [d]", ylabel="y [d]",
          title=f"bed from above\n{len(bed)} spheres, {len(bed) / (L_x * L_y):.2f} per d$^2$")
    save(fig, os.path.join(out, "packing.png"), formats)


def run_plots(out, s, t):
    """All plots of one analysis into ``out``, in the formats of its ``analysis.figure_format``."""
    fm = formats_of(s.get("settings", {}).get("analysis.figure_format", "png"))
    plot_packing(out, s, t, formats=fm)
    plot_profile(out, s, t, fm)
    plot_coordination(out, s, fm)
    if "gofr" in t:
        plot_gofr(out, s, t, fm)
    if "zeta" in t:
        plot_zeta(out, s, t, fm)
