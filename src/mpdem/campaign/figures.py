"""The paper's figures (Figs. 2-9) from the parameter sets of ``mpdem collect``.

::

    OUT/fig2_z_vs_mu.png ... OUT/fig9_phi_i.png   (``FIGURES``: name, file, what it shows)

``make_figures`` draws every figure the sets have data for, with the paper's
values as open markers / dashes, and says why any other is not made. Figs.
2-6 and 8 use the sets at the paper's k_n and phi_i (else the most populated
(k_n, phi_i)); Figs. 4-6 and 8 average the runs' analysis/*.csv tables per
bin over the seeds; Figs. 7 and 9 draw the eq. 7 and eq. 9 fits of
``collect.make_fits``. Error bars are the standard error over the seeds.
"""
from __future__ import annotations

import math
import os
from collections import Counter

import numpy as np

from ..analysis import fits
from . import paper, pooled
from .runs import NAN, families, fmt_kn, fmt_pm, num, read_table


def _seeds(n):
    return f"{n} seed" + ("" if n == 1 else "s")


def _label(fam, varying, keys=("mu", "epsilon")):
    names = {"mu": "μ", "epsilon": "ε", "phi_i": "φ_i", "k_n": "k_n"}
    parts = [f"{names[k]} = {fmt_kn(fam[k]) if k == 'k_n' else format(fam[k], 'g')}" for k in keys if k in fam]
    return ", ".join(parts + [f"{k} = {fam[k]}" for k in varying if k not in keys and k in fam])


# follow epsilon and k_n: named in a label only when the families differ in nothing else
_QUIET = ("k_t", "gamma_n", "dt", "k_t/k_n", "gamma_n/sqrt(k_n)")


def _varying(dicts):
    """The keys whose values differ between the family dicts (what tells their curves apart)."""
    # every family's keys: an extra physics key (stop.energy) is only in the families that set it
    keys = list(dict.fromkeys(k for d in dicts for k in d))
    vary = [k for k in keys if len({repr(d.get(k)) for d in dicts}) > 1]
    loud = [k for k in vary if k not in _QUIET]
    distinct = len({tuple(repr(d.get(k)) for k in loud) for d in dicts}) == len(dicts)
    return loud if distinct else vary


class Figures:
    """The paper's figures from the sets; each ``figN`` returns None when made, else why not."""

    def __init__(self, sets, fit_res, out, formats=("png",)):
        from ..analysis import plots  # matplotlib only once figures are drawn
        self.plt, self.formats = plots.plt, tuple(formats)
        self.save = lambda fig, path: plots.save(fig, path, self.formats)
        self.sets, self.fits, self.out = sets, fit_res, out
        self._tables, self.notes = {}, {}
        self.slice, self.slice_text = self._mu_slice()
        self.curves = families(self.slice, "contact.mu")
        self.per_mu = self._per_mu_curve()

    # ---- selection
    def _mu_slice(self):
        """Sets at the paper's k_n and phi_i when there are any, else at the most populated (k_n, phi_i)."""
        ref = [s for s in self.sets if paper.is_reference(s.p("k_n"), s.p("phi_i"))]
        if ref:
            return ref, f"k_n = {fmt_kn(paper.REFERENCE['k_n'])}, φ_i ≈ {paper.REFERENCE['phi_i']:g}"
        if not self.sets:
            return [], ""
        c = Counter((s.p("k_n"), s.p("phi_i")) for s in self.sets)
        (k, phi), _ = max(c.items(), key=lambda kv: (kv[1], -kv[0][0]))
        return ([s for s in self.sets if (s.p("k_n"), s.p("phi_i")) == (k, phi)],
                f"k_n = {fmt_kn(k)}, φ_i = {phi:g} (no runs at the paper's k_n = 2e5, φ_i ≈ 0.13)")

    def _per_mu_curve(self):
        """The mu-curve of Figs. 4-6 and 8: epsilon 0.88 (the paper's Fig. 4) when present, else the longest."""
        if not self.curves:
            return None
        pref = [c for c in self.curves if c[0]["epsilon"] == paper.PZ_EPSILON] or self.curves
        return max(pref, key=lambda c: len(c[1]))

    def _small(self, sets):
        return any(paper.is_small_pile(s.p("N"), s.p("L_x"), s.p("L_y")) for s in sets)

    # ---- per-run tables
    def table(self, run, name):
        """Columns of RUN/analysis/<name>.csv as float arrays, None when missing or unreadable."""
        key = (run.path, name)
        if key not in self._tables:
            self._tables[key] = read_table(run.path, name)
        return self._tables[key]

    def mean_curve(self, s, name, ycol, bins):
        """Mean and standard error over the set's runs of column ``ycol`` of ``name``.csv.

        ``bins`` = (lower, upper) bin-edge columns. Runs without the columns,
        or whose bins differ from the first run's (over their common length),
        are left out (listed in ``notes``).

        Returns
        -------
        None, or (lower edges (nb,), upper edges (nb,), mean (nb,), sem (nb,)
        (nan with one run), runs used)
        """
        lo, hi = bins
        got = [(r, t) for r, t in ((r, self.table(r, name)) for r in s.runs)
               if t is not None and {ycol, lo, hi} <= set(t)]
        if not got:
            return None
        nb = min(len(t[lo]) for _, t in got)
        x0 = got[0][1][lo][:nb]
        use = [(r, t) for r, t in got if np.array_equal(t[lo][:nb], x0)]
        left = [r.path for r in s.runs if r.path not in {u.path for u, _ in use}]
        if left:
            self.notes.setdefault(name, []).append(f"{s.id}: left out (no {ycol} in {name}.csv, or other bins): "
                                                   f"{', '.join(left)}")
        Y = np.array([t[ycol][:nb] for _, t in use])
        sem = Y.std(0, ddof=1) / np.sqrt(len(use)) if len(use) >= 2 else np.full(nb, NAN)
        return x0, use[0][1][hi][:nb], Y.mean(0), sem, len(use)

    # ---- drawing helpers
    def _points(self, ax, x, m, e, label, color=None, marker="o", ls="-"):
        """Filled markers joined by a line, error bars where there is a standard error."""
        x, m, e = (np.asarray(v, float) for v in (x, m, e))
        line, = ax.plot(x, m, marker=marker, ls=ls, color=color, ms=5, lw=1, label=label)
        ok = np.isfinite(e)
        if ok.any():
            ax.errorbar(x[ok], m[ok], yerr=e[ok], fmt="none", ecolor=line.get_color(), capsize=3, lw=1)
        return line, bool((~ok).any())

    def _paper_point(self, ax, x, y, err, label, color="k", marker="s"):
        ax.errorbar([x], [y], yerr=None if err is None else [err], fmt=marker, mfc="none", mec=color, ecolor=color,
                    ms=9, mew=1.5, capsize=3, label=label)

    def _one_seed_note(self, ax, any_single):
        if any_single:
            ax.text(0.01, 0.01, "points without error bars: a single seed", transform=ax.transAxes, fontsize=7,
                    color="grey", va="bottom")

    def _legend(self, ax):
        """The axes' legend below them, outside the data (``plots.save`` keeps it in the figure): two
        columns when long and the axes are the figure's only ones (side by side, each its own column)."""
        h, lab = ax.get_legend_handles_labels()
        seen = {}
        for hh, ll in zip(h, lab):
            seen.setdefault(ll, hh)
        if seen:
            ax.legend(seen.values(), seen.keys(), fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16),
                      ncol=2 if len(seen) > 5 and len(ax.figure.axes) == 1 else 1, frameon=False)

    def _file(self, name):
        return os.path.join(self.out, name)

    # ---- Figs. 2 and 3
    def _vs_mu(self, q, fname, ylabel, title):
        if not self.curves:
            return "no parameter sets"
        plt = self.plt
        fig, ax = plt.subplots(figsize=(6, 4.2))
        varying = _varying([f for f, _ in self.curves])
        single = False
        for fam, members in self.curves:
            st = [s.stat(q) for s in members]
            _, one = self._points(ax, [s.p("mu") for s in members], [v[0] for v in st], [v[1] for v in st],
                                  _label(fam, varying, ("epsilon",)))
            single |= one
        mus = {s.p("mu") for _, m in self.curves for s in m}
        eps = {f["epsilon"] for f, _ in self.curves}
        for p in paper.POINTS:
            if p["quantity"] == q and p["mu"] is not None and (p["epsilon"] is None or eps & set(p["epsilon"])):
                self._paper_point(ax, p["mu"], p["value"], p["err"], "paper (N = 20000, 20d box)")
        for p in paper.FLOW_ARREST:
            if p["quantity"] == q:
                self._paper_point(ax, p["mu"], p["value"], None, "paper: flow arrest (other protocol)", "grey", "D")
        if self._small(self.slice):
            for p in paper.SMALL_POINTS:
                if p["quantity"] == q:
                    self._paper_point(ax, p["mu"], p["value"], None, "7.1 reference (N = 2000, 10d box)",
                                      "tab:red", "^")
        pos = sorted(m for m in mus | {0.5} if m > 0)
        ax.set_xscale("symlog", linthresh=pos[0], linscale=0.5)
        ticks = sorted(mus | {0.0, 0.5})
        ax.set_xticks(ticks, [f"{m:g}" for m in ticks], fontsize=7)
        ax.minorticks_off()
        ax.set(xlabel="μ", ylabel=ylabel, title=f"{title}, {self.slice_text}")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self.save(fig, self._file(fname))

    def fig2(self):
        """z against mu, one curve per epsilon."""
        return self._vs_mu("z", "fig2_z_vs_mu.png", "bulk z", "Fig. 2: coordination")

    def fig3(self):
        """phi_f against mu, one curve per epsilon."""
        return self._vs_mu("phi", "fig3_phi_vs_mu.png", "bulk φ_f", "Fig. 3: packing fraction")

    # ---- Figs. 4, 5, 6, 8: one curve per mu
    def _mu_sets(self):
        fam, members = self.per_mu
        return fam, members, self.plt.cm.viridis(np.linspace(0, 0.9, max(len(members), 1)))

    def _mu_curves(self, name, ycol, bins, keep=lambda s: True):
        """(family, [(set, colour, ``mean_curve``)]) of the mu sets kept whose runs have the column."""
        fam, members, colors = self._mu_sets()
        got = [(s, c, self.mean_curve(s, name, ycol, bins)) for s, c in zip(members, colors) if keep(s)]
        return fam, [g for g in got if g[2] is not None]

    def fig4(self):
        """P(z) per mu at epsilon 0.88 (when present)."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, members, colors = self._mu_sets()
        fig, ax = self.plt.subplots(figsize=(6, 4.2))
        single = False
        for s, c in zip(members, colors):
            P = [r.s.get("P_z") for r in s.runs]
            P = np.array([p for p in P if isinstance(p, list) and len(p) == 13 and None not in p], float)
            if not len(P):
                self.notes.setdefault("summary.json", []).append(f"{s.id}: no P_z in the summaries")
                continue
            sem = P.std(0, ddof=1) / np.sqrt(len(P)) if len(P) >= 2 else np.full(P.shape[1], NAN)
            _, one = self._points(ax, np.arange(P.shape[1]), P.mean(0), sem, f"μ = {s.p('mu'):g} ({_seeds(len(P))})", c)
            single |= one
        if not ax.lines:
            self.plt.close(fig)
            return "no P_z in the summaries"
        if self._small(members):
            for mu, (n, pk) in paper.SMALL_PZ_PEAK.items():
                if mu in {s.p("mu") for s in members}:
                    self._paper_point(ax, n, pk, None, f"7.1 reference peak, μ = {mu:g} (N = 2000, 10d box)",
                                      "tab:red", "^")
        ax.set(xlabel="contacts n (last: n ≥ 12)", ylabel="P(n)", xticks=range(0, 13),
               title=f"Fig. 4: P(z), ε = {fam['epsilon']:g}, {self.slice_text}")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self.save(fig, self._file("fig4_P_z.png"))

    def fig5(self):
        """g(r) per mu, mean over seeds of g per bin, curves shifted by 1."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, curves = self._mu_curves("gofr", "g", ("r_lo", "r_hi"))
        if not curves:
            return "no gofr.csv in the runs"
        fig, ax = self.plt.subplots(figsize=(6, 5))
        top = 1.0
        for drawn, (s, c, (r_lo, r_hi, g, _, n)) in enumerate(curves):
            r = 0.5 * (r_lo + r_hi)
            ax.plot(r, g + drawn, color=c, lw=0.8, label=f"μ = {s.p('mu'):g} ({_seeds(n)}) + {drawn}")
            top = max(top, float(np.nanmax(g[r > 1.05], initial=1.0)) + drawn)
        ax.set(xlabel="r / d", ylabel="g(r) + shift", xlim=(0.8, None), ylim=(0, top * 1.15),
               title=f"Fig. 5: g(r), ε = {fam['epsilon']:g}, mean over seeds (first peak cut)")
        self._legend(ax)
        self.save(fig, self._file("fig5_gofr.png"))

    def fig6(self):
        """Near-contact g against xi = r/d - 1, log-log, with the paper's slope -0.52."""
        if self.per_mu is None:
            return "no parameter sets"
        fam, curves = self._mu_curves("gofr_near", "g", ("xi_lo", "xi_hi"))
        if not curves:
            return "no gofr_near.csv in the runs"
        fig, ax = self.plt.subplots(figsize=(5.5, 4.5))
        anchor, window = [], []
        for s, c, (xi_lo, xi_hi, g, _, n) in curves:
            xi = np.sqrt(xi_lo * xi_hi)
            ok = g > 0
            a, ae, na = s.stat("alpha")
            lab = f"μ = {s.p('mu'):g}: α = " + (f"{a:.3f}" if na else "n/a") + (f" ± {ae:.3f}" if na >= 2 else "")
            ax.loglog(xi[ok], g[ok], "o-", color=c, ms=3, lw=0.7, label=lab)
            fw = [(r.s.get("alpha_fit") or {}) for r in s.runs]
            lo, hi = (np.nanmedian([num(f.get(k)) for f in fw]) for k in ("xi_lo", "xi_hi"))
            if math.isfinite(lo) and math.isfinite(hi):
                w = ok & (xi >= lo) & (xi <= hi)
                anchor += list(np.log(g[w]) + paper.ALPHA * np.log(xi[w]))
                window += [lo, hi]
        if anchor:
            xs = np.array([min(window), max(window)])
            ax.loglog(xs, np.exp(np.mean(anchor)) * xs ** -paper.ALPHA, "k--", lw=1.5,
                      label=f"paper: slope −{paper.ALPHA} (α = {paper.ALPHA} ± {paper.ALPHA_ERR}), through the data")
        ax.set(xlabel="ξ = r/d − 1", ylabel="g", title=f"Fig. 6: near contact, ε = {fam['epsilon']:g}")
        self._legend(ax)
        self.save(fig, self._file("fig6_gofr_near.png"))

    def fig8(self):
        """P(zeta) per frictional mu (and F_t/F_n for mu >= 1 when present)."""
        if self.per_mu is None:
            return "no parameter sets"
        zb = ("zeta_lo", "zeta_hi")
        fam, got = self._mu_curves("zeta", "P", zb, keep=lambda s: s.p("mu") > 0)
        if not got:
            return "no zeta.csv in the runs (mu = 0 has none)"
        _, ratio = self._mu_curves("zeta", "P_ratio", zb, keep=lambda s: s.p("mu") >= 1)
        fig, axes = self.plt.subplots(1, 2 if ratio else 1, figsize=(11 if ratio else 6, 4.2), squeeze=False)
        for s, c, (lo, hi, P, e, n) in got:
            x = 0.5 * (lo + hi)
            m = s.stat("mobilised_fraction")[0]
            mob = f", {100 * m:.1f}% fully mobilised" if math.isfinite(m) else ""
            axes[0, 0].plot(x, P, ".-", color=c, lw=1, label=f"μ = {s.p('mu'):g} ({_seeds(n)}){mob}")
            if n >= 2:
                axes[0, 0].fill_between(x, P - e, P + e, color=c, alpha=0.2, lw=0)
        axes[0, 0].set(xlabel="ζ = |F_t| / μF_n", ylabel="P / max P (mean over seeds)", ylim=(0, 1.1),
                       title=f"Fig. 8: P(ζ), ε = {fam['epsilon']:g} (paper: almost all ζ < 1)")
        self._legend(axes[0, 0])
        for s, c, (lo, hi, P, e, n) in ratio:
            axes[0, 1].plot(0.5 * (lo + hi), P, ".-", color=c, lw=1, label=f"μ = {s.p('mu'):g} ({_seeds(n)})")
        if ratio:
            axes[0, 1].set(xlabel="|F_t| / F_n", ylabel="P / max P", ylim=(0, 1.1),
                           title="μ ≥ 1 (paper: these collapse)")
            self._legend(axes[0, 1])
        self.save(fig, self._file("fig8_P_zeta.png"))

    # ---- Fig. 7
    def fig7(self):
        """z against k_n with the eq. 7 fit per family, and z - z_inf log-log."""
        ent = self.fits["eq7"]
        if not ent:
            return "no family of sets with >= 2 values of k_n"
        plt = self.plt
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
        varying = _varying([e["family"] for e in ent])
        ks = [k for e in ent for k in e["k_n"]] + list(paper.EQ7_MU0_POINTS)
        kk = np.geomspace(min(ks), max(ks), 100)
        single = False
        for e in ent:
            zs = np.array([v if v is not None else NAN for v in e["z_sem"]])
            line, one = self._points(ax, e["k_n"], e["z"], zs, _label(e["family"], varying), ls="none")
            single |= one
            if e["status"] != "fitted":
                continue
            c = line.get_color()
            ax.plot(kk, fits.eq7(kk, e["z_inf"], e["a"], e["alpha_n"]), "-", color=c, lw=1,
                    label=f"eq. 7: z∞ = {fmt_pm(e['z_inf'], e['z_inf_err'], 3)}, "
                          f"α_n = {fmt_pm(e['alpha_n'], e['alpha_n_err'], 2)}")
            dz = np.array(e["z"]) - e["z_inf"]
            ok = dz > 0
            bx.loglog(np.array(e["k_n"])[ok], dz[ok], "o", color=c, ms=5, label=_label(e["family"], varying))
            if np.any(ok & np.isfinite(zs)):
                bx.errorbar(np.array(e["k_n"])[ok & np.isfinite(zs)], dz[ok & np.isfinite(zs)],
                            yerr=zs[ok & np.isfinite(zs)], fmt="none", ecolor=c, capsize=3)
            bx.loglog(kk, e["a"] * (kk / fits.K_REF) ** -e["alpha_n"], "-", color=c, lw=1)
            if e["family"]["mu"] > 0 and ok.any():
                k0, d0 = np.array(e["k_n"])[ok][0], dz[ok][0]
                bx.loglog(kk, d0 * (kk / k0) ** -paper.EQ7_FRICTIONAL_ALPHA_N, ":", color=c, lw=1,
                          label="paper: ∝ k_n^(−1/4) (μ > 0)")
        P = paper.EQ7_MU0
        pk = np.array(sorted(paper.EQ7_MU0_POINTS))
        pz = np.array([paper.EQ7_MU0_POINTS[k] for k in pk])
        lab = f"paper μ = 0: z∞ = {P['z_inf']} ± {P['z_inf_err']}, α_n = {P['alpha_n']}"
        ax.plot(kk, paper.eq7_mu0(kk), "k--", lw=1, label=lab)
        ax.plot(pk, pz, "ks", mfc="none", ms=8, label="paper μ = 0 (2e5 measured, others derived)")
        bx.loglog(kk, paper.eq7_mu0(kk) - P["z_inf"], "k--", lw=1, label="paper μ = 0")
        bx.loglog(pk, pz - P["z_inf"], "ks", mfc="none", ms=8)
        ax.set(xscale="log", xlabel="k_n [mg/d]", ylabel="bulk z", title="Fig. 7: z(k_n)")
        bx.set(xlabel="k_n [mg/d]", ylabel="z − z∞ (fitted z∞; paper: its own)", title="approach to z∞")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self._legend(bx)
        self.save(fig, self._file("fig7_z_vs_kn.png"))

    # ---- Fig. 9
    def fig9(self):
        """phi_f and z against phi_i with the eq. 9 fit per family."""
        ent = self.fits["eq9"]
        if not ent:
            return "no family of sets with >= 2 values of phi_i"
        fig, (ax, bx) = self.plt.subplots(1, 2, figsize=(11, 4.2))
        varying = _varying([e["family"] for e in ent])
        xx = np.linspace(min(min(e["phi_i"]) for e in ent + [{"phi_i": list(paper.EQ9_POINTS)}]),
                         max(max(e["phi_i"]) for e in ent + [{"phi_i": list(paper.EQ9_POINTS)}]), 100)
        single = False
        for e in ent:
            sem = [v if v is not None else NAN for v in e["phi_sem"]]
            line, one = self._points(ax, e["phi_i"], e["phi"], sem, _label(e["family"], varying), ls="none")
            single |= one
            if e["status"] == "fitted":
                ax.plot(xx, fits.eq9(xx, e["A"], e["B"], e["C"]), "-", color=line.get_color(), lw=1,
                        label=f"eq. 9: A = {e['A']:.4f}, B = {e['B']:.4f}, C = {e['C']:.2f}")
            zs = [v if v is not None else NAN for v in e["z_sem"]]
            _, one = self._points(bx, e["phi_i"], e["z"], zs, _label(e["family"], varying), line.get_color())
            single |= one
        E = paper.EQ9
        ax.plot(xx, paper.eq9_paper(xx), "k--", lw=1,
                label=f"paper eq. 9 (μ = {E['mu']:g}, ε = {E['epsilon']:g}): {E['A']} + {E['B']} exp(−{E['C']} φ_i)")
        ax.plot(list(paper.EQ9_POINTS), list(paper.EQ9_POINTS.values()), "ks", mfc="none", ms=8, label="paper")
        ax.set(xlabel="φ_i", ylabel="bulk φ_f", title="Fig. 9: φ_f(φ_i)")
        bx.set(xlabel="φ_i", ylabel="bulk z", title="z(φ_i) (paper: decreases with φ_i)")
        self._one_seed_note(ax, single)
        self._legend(ax)
        self._legend(bx)
        self.save(fig, self._file("fig9_phi_i.png"))


    # ---- the measures of a pile under gravity (docs/model.md 6.5, 6.6, 6.10)
    def _set_label(self, s):
        return (f"{s.id}: μ = {s.p('mu'):g}, ε = {s.p('epsilon'):g}, k_n = {fmt_kn(s.p('k_n'))}, "
                f"N = {s.p('N')} ({_seeds(len(s.runs))})")

    def _pooled(self, key):
        got = {e["set"]: e for e in self.fits.get(key, [])}
        return [(s, got[s.id]) for s in self.sets if s.id in got]

    def fig10(self):
        """The local slope of g(xi): alpha on half-decade windows, seeds pooled, per set."""
        got = [(s, e) for s, e in self._pooled("alpha") if e["local"]]
        if not got:
            return "no run has the local-slope statistics (alpha_local)"
        fig, ax = self.plt.subplots(figsize=(7, 4.5))
        for s, e in got:
            pts = [p for p in e["local"] if math.isfinite(p["alpha"]) and p["n"] >= 50]
            if pts:
                ax.errorbar([p["xi"] for p in pts], [p["alpha"] for p in pts], [p["alpha_err"] for p in pts],
                            fmt="o-", ms=3, lw=0.8, capsize=2, label=self._set_label(s))
        ax.axhline(paper.ALPHA, color="k", ls="--", lw=1, label=f"paper α = {paper.ALPHA} ± {paper.ALPHA_ERR}")
        ax.axhline(0.38, color="grey", ls=":", lw=1, label="jammed frictionless spheres ≈ 0.38-0.4 (later work)")
        ax.set(xscale="log", xlabel="ξ = r/d − 1 (window centre, ±1/4 decade)", ylabel="α (local)",
               title="local slope −d ln g / d ln ξ (maximum likelihood, windows with ≥ 50 gaps)")
        self._legend(ax)
        self.save(fig, self._file("fig10_alpha_local.png"))

    def fig11(self):
        """z against depth below the surface per set, and z against sqrt(delta / d) with the overlap fits."""
        got = [(s, e) for s, e in self._pooled("depth")]
        if not got:
            return "no run has a depth profile (bands)"
        fig, (ax, bx) = self.plt.subplots(1, 2, figsize=(12, 4.5))
        for s, e in got:
            d = 0.5 * (np.array(e["depth_lo"], float) + np.array(e["depth_hi"], float))
            z = np.array(e["z"], float)
            inb = np.array(e["in_bulk"], bool)
            line, = ax.plot(d, z, "o-", ms=3, lw=0.8, label=self._set_label(s))
            ax.plot(d[inb], z[inb], "o", ms=6, mfc="none", color=line.get_color())
            for r in s.runs:
                b = r.s.get("bands")
                if b:
                    sel = np.array(b["in_bulk"], bool)
                    ov = np.array([np.nan if v is None else v for v in b["overlap_mean"]], float)
                    zz = np.array([np.nan if v is None else v for v in b["z"]], float)
                    bx.plot(np.sqrt(ov[sel]), zz[sel], "o", ms=3, color=line.get_color())
        for e in self.fits.get("overlap", []):
            if e["status"] == "fitted":
                xs = np.sqrt(np.array([0.0, e["delta_max"]]))
                f = e["family"]
                what = ", ".join(x for x in ("" if f.get("model", "hooke") == "hooke" else f["model"],
                                             "ladder" if any(k.startswith("stiffened") for k in f) else "") if x)
                zc = pooled.z_c_text(e, why=False)
                bx.plot(xs, e["z_c"] + e["A"] * xs, "-", lw=1,
                        label=f"z_c = {zc} (μ = {f['mu']:g}, N = {f['N']}{', ' + what if what else ''})")
        bx.axhline(6.0, color="k", ls=":", lw=1, label="isostatic (μ = 0): 6")
        ax.set(xlabel="depth below the surface [d]", ylabel="z (band)",
               title="z per depth band (circled: in the bulk slab)")
        bx.set(xlabel="(δ/d)^(1/2), δ the band's mean overlap", ylabel="z (band)",
               title="z − z_c = A (δ/d)^(1/2) over the bulk bands")
        self._legend(ax)
        self._legend(bx)
        self.save(fig, self._file("fig11_depth.png"))

    def fig12(self):
        """P(f), f = F_n / its depth band's mean, per set, seeds pooled."""
        got = self._pooled("P_f")
        if not got:
            return "no run has P(f)"
        from ..analysis.bands import F_BIN
        fig, ax = self.plt.subplots(figsize=(6.5, 4.5))
        for s, e in got:
            P = np.array(e["P"], float)
            f = F_BIN * (np.arange(len(P)) + 0.5)
            ok = P > 0
            ax.semilogy(f[ok], P[ok], "o-", ms=3, lw=0.8,
                        label=self._set_label(s) + f"; β = {e['tail_rate']:.2f}")
        ax.set(xlabel="f = F_n / ⟨F_n⟩ (depth band)", ylabel="P(f)", title="normal-force distribution, bulk contacts")
        self._legend(ax)
        self.save(fig, self._file("fig12_P_f.png"))


FIGURES = (  # name, file, what it shows
    ("fig2", "fig2_z_vs_mu.png", "bulk z against mu, one curve per epsilon, paper values as open markers"),
    ("fig3", "fig3_phi_vs_mu.png", "bulk phi_f against mu, one curve per epsilon, paper values as open markers"),
    ("fig4", "fig4_P_z.png", "P(z) (mean over seeds) per mu at epsilon 0.88 when present"),
    ("fig5", "fig5_gofr.png", "g(r) (mean over seeds per bin) per mu, curves shifted by 1"),
    ("fig6", "fig6_gofr_near.png", "near-contact g against xi = r/d - 1, log-log, per mu, paper slope -0.52"),
    ("fig7", "fig7_z_vs_kn.png", "z against k_n with the eq. 7 fit per (mu, epsilon) family; z - z_inf log-log"),
    ("fig8", "fig8_P_zeta.png", "P(zeta) (mean over seeds) per frictional mu; F_t/F_n for mu >= 1"),
    ("fig9", "fig9_phi_i.png", "phi_f and z against phi_i with the eq. 9 fit, paper eq. 9 dashed"),
    ("fig10", "fig10_alpha_local.png", "the local slope of g(xi): alpha on half-decade windows, seeds pooled, per set"),
    ("fig11", "fig11_depth.png", "z per depth band, and z against (delta/d)^(1/2) with the overlap fit per family"),
    ("fig12", "fig12_P_f.png", "P(f), the normal force over its depth band's mean, per set, seeds pooled"),
)


def make_figures(sets, fit_res, out, log=print, formats=("png",)):
    """Every figure the sets have data for, in each of ``formats`` (png, pdf, svg; the README shows
    the PNGs when made, else the first format).

    Returns
    -------
    {name: {file, shows, made, reason}} for each of ``FIGURES`` (reason None
    when made), and "_notes" ({table: [what was left out]}) and "_slice" (the
    k_n and phi_i of Figs. 2-6 and 8, as text).
    """
    figs = Figures(sets, fit_res, out, formats)
    res = {}
    show = "png" if "png" in formats else formats[0]
    for name, fname, shows in FIGURES:
        why = getattr(figs, name)()
        stem = os.path.splitext(fname)[0]
        res[name] = {"file": f"{stem}.{show}", "files": [f"{stem}.{f}" for f in formats], "shows": shows,
                     "made": why is None, "reason": why}
        log(f"collect: {name}: " + (f"wrote {fname}" if why is None else f"not made ({why})"))
    for name, notes in figs.notes.items():
        for n in notes:
            log(f"collect: note: {name}: {n}")
    res["_notes"] = figs.notes
    res["_slice"] = figs.slice_text
    return res
