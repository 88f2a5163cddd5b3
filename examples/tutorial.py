# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # mpdem tutorial: from a first pile to the paper's Fig. 2
#
# This notebook pours a small pile of spheres, looks at it, measures it, and then repeats the pour
# at several friction coefficients to draw z(μ), the coordination number against friction: Fig. 2
# of Silbert, Ertaş, Grest, Halsey and Levine, Phys. Rev. E 65, 031304 (2002), at a small size.
#
# It is a jupytext "percent" script: `python examples/tutorial.py` runs it as it is (figures go to
# files), and `jupytext --to notebook examples/tutorial.py` makes the notebook (figures inline).
# `make test` runs it whole (tests/test_examples.py): half a minute to a minute on one core.
#
# Units are reduced: sphere diameter d = 1, mass m = 1, gravity g = 1, time τ = sqrt(d/g).

# %%
import os
import sys

import matplotlib
if "ipykernel" not in sys.modules:      # run as a script: figures to files only
    matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import mpdem

OUT = os.environ.get("MPDEM_TUTORIAL_OUT", "runs/tutorial")
os.makedirs(OUT, exist_ok=True)


def show(fig, name):
    """Save the figure as OUT/name; in a notebook it also shows inline (at the cell's end)."""
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, name), dpi=90)
    if "ipykernel" not in sys.modules:
        plt.close(fig)


# %% [markdown]
# ## 1. A first pile
#
# A config is the built-in example (1500 spheres in a 10 d × 10 d box, periodic in x and y, Hookean
# contacts with k_n = 2×10⁵ m g/d, restitution 0.88, friction μ = 0.5) with any key changed by name
# (docs/config.md lists them all). We make it small: 150 spheres in 4 d × 4 d, softer springs
# (k_n = 2×10⁴: a time step √10 times longer) and a looser stop rule (the pile counts as at rest
# when its kinetic energy per sphere, averaged over 1 τ, is below 10⁻⁵ m g d).

# %%
SMALL = {"pour.N": 150, "box.L_x": 4.0, "box.L_y": 4.0, "pour.phi_i": 0.3, "contact.k_n": 2e4,
         "stop.E_stop": 1e-5, "run.max_steps": 400_000}
cfg = mpdem.load_config(**SMALL)
print(cfg.pour.N, "spheres, mu =", cfg.contact.mu, ", dt =", cfg.integration.dt, "tau")

# %% [markdown]
# `mpdem.run` makes the rough bed (frozen spheres), inserts the spheres at random, lets them fall and
# steps them until the stop rule holds. Everything goes into the run directory: the resolved config,
# the log, `thermo.csv`, the final state `final.h5` and `summary.json`.

# %%
r = mpdem.run(cfg, os.path.join(OUT, "first"), force=True)
print(r.status, "after", r.steps, "steps; digest", r.digest[:16])

# %% [markdown]
# The pile came to rest. `thermo.csv` has one row per sample of the kinetic energy: the pour, the
# impacts, then the decay to rest.

# %%
import csv  # noqa: E402

with open(os.path.join(r.out, "thermo.csv"), newline="") as fh:
    rows = list(csv.DictReader(fh))
t = np.array([float(x["time"]) for x in rows])
ek = np.array([float(x["ek"]) for x in rows])
fig, ax = plt.subplots(figsize=(6, 3))
ax.semilogy(t, ek)
ax.axhline(cfg.stop.E_stop, ls=":", c="k", label="E_stop")
ax.set(xlabel="t [τ]", ylabel="E_k / N [m g d]", title="settling")
ax.legend()
show(fig, "settling.png")

# %% [markdown]
# ## 2. Looking at it
#
# `mpdem.read_state` gives the final state's arrays, sorted by id: positions `x` (n, 3) [d], the
# `fixed` flag of the bed spheres, and the contact list (`id_i`, `id_j`, the normal force `F_n`
# [m g], ...).

# %%
s = mpdem.read_state(r.final)
mobile = s["fixed"] == 0
print(len(s["x"]), "spheres,", int(mobile.sum()), "mobile,", len(s["id_i"]), "contacts")
contacts = np.bincount(np.searchsorted(s["id"], np.concatenate([s["id_i"], s["id_j"]])), minlength=len(s["id"]))

fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 4))
sc = ax.scatter(s["x"][mobile, 0], s["x"][mobile, 2], c=contacts[mobile], s=25, cmap="viridis")
ax.scatter(s["x"][~mobile, 0], s["x"][~mobile, 2], c="0.6", s=25)
ax.set(xlabel="x [d]", ylabel="height [d]", aspect="equal", title="side view (grey: bed)")
fig.colorbar(sc, ax=ax, label="contacts")
bx.hist(s["F_n"] / s["F_n"].mean(), bins=30)
bx.set(xlabel="F_n / <F_n>", ylabel="contacts", title="normal forces")
show(fig, "pile.png")

# %% [markdown]
# ## 3. Measuring it
#
# `mpdem.analyze` makes the paper's measurements. The bulk is a slab away from the bed and from the
# free surface (3 d margins for a pile this short); z is the mean number of contacts of its spheres
# and φ its packing fraction. The backbone drops the contacts that carry almost no force and the
# spheres that cannot carry their weight (rattlers).

# %%
a = mpdem.analyze(r.final)
print(f"bulk: heights {a['z1']:.2f} to {a['z2']:.2f} d, {a['n_bulk']} spheres")
print(f"z = {a['z']:.3f}, phi = {a['phi']:.4f}, backbone z = {a['backbone']['z']:.3f}")
n, P = a["arrays"]["P_z"]
fig, ax = plt.subplots(figsize=(5, 3))
ax.bar(n, P)
ax.set(xlabel="contacts n", ylabel="P(n)", title=f"mu = 0.5: z = {a['z']:.2f}")
show(fig, "P_n.png")

# %% [markdown]
# ## 4. Friction: z against μ (Fig. 2)
#
# Friction lets a sphere rest on fewer contacts: a frictionless pile needs about 6 a sphere (the
# isostatic count 2 × 3 of three-dimensional frictionless spheres), a very rough one about 4. The
# same pour at a few values of μ, one seed each (the paper averages seeds of 20 000 spheres; the
# `friction_sweep.py` example runs a table of them with `mpdem sweep`):

# %%
MUS = [0.0, 0.1, 0.5, 1.0, 10.0]
z_of_mu, phi_of_mu = {0.5: a["z"]}, {0.5: a["phi"]}     # mu = 0.5 is the first pile
for mu in MUS:
    if mu in z_of_mu:
        continue
    rm = mpdem.run(mpdem.load_config(**SMALL, **{"contact.mu": mu}), os.path.join(OUT, f"mu{mu:g}"), force=True)
    am = mpdem.analyze(rm.final)
    z_of_mu[mu], phi_of_mu[mu] = am["z"], am["phi"]
    print(f"mu = {mu:g}: {rm.status} after {rm.steps} steps, z = {am['z']:.3f}, phi = {am['phi']:.4f}")

# %% [markdown]
# The paper's values at its size (docs/model.md 7): z = 6.144 at μ = 0 and 4.90 at μ = 0.5.
# A 150-sphere pile has a bulk of a few dozen spheres, so expect its z within a few tenths of them.

# %%
mu = np.array(MUS)
z = np.array([z_of_mu[m] for m in MUS])
phi = np.array([phi_of_mu[m] for m in MUS])
fig, (ax, bx) = plt.subplots(1, 2, figsize=(9, 3.5))
ax.plot(mu, z, "o-", label="this notebook (150 spheres)")
ax.plot([0.0, 0.5], [6.144, 4.90], "k*", ms=10, label="the paper (20 000 spheres)")
ax.set_xscale("symlog", linthresh=0.1)
ax.set(xlabel="μ", ylabel="z", title="Fig. 2: coordination number")
ax.legend()
bx.plot(mu, phi, "s-")
bx.set_xscale("symlog", linthresh=0.1)
bx.set(xlabel="μ", ylabel="φ", title="packing fraction")
show(fig, "fig2.png")
for m, zz, p in zip(MUS, z, phi):
    print(f"mu = {m:g}: z = {zz:.3f}, phi = {p:.4f}")

# %% [markdown]
# ## Where next
#
# - The paper's size: `pour.N = 20000`, `box.L_x = box.L_y = 20`, the default k_n and stop rule
#   (hours a run on one core; minutes on a GPU: `engine.device = "gpu"`).
# - Many runs: `mpdem sweep TABLE --out RUNS` (collected into RUNS/collect, or `--collect DIR`) and
#   `mpdem collect RUNS --out DIR` (examples/friction_sweep.py).
# - Stiffer springs from the same packing: `mpdem.stiffen_config` (examples/stiffen_pile.py).
# - The API reference: `make docs`, then build/docs/html/reference.html.
