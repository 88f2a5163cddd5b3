"""Run configuration: TOML in reduced units -> one frozen, validated Config.

Every parameter has a documented default here (docs/config.md's reference
is generated from ``SCHEMA``). A few defaults are derived from other values
(docs/model.md): k_t = 2 k_n / 7, gamma_n from epsilon (eq. 4-5),
dt = 1e-4 sqrt(2e5 / k_n), E_stop = 1e-8 (k_n / 2e5)^(-3/4). Validation
(docs/model.md section 8) happens here, before any work starts: an error names
the key, the value and what is accepted.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from types import MappingProxyType

from .errors import ConfigError
from .kernels.models import MODELS

REQUIRED = object()   # marks a key with no default
DERIVED = object()    # marks a default computed from other keys


@dataclass(frozen=True)
class Key:
    """One config key of ``SCHEMA``.

    ``restart``: a restart may change it with --set (it does not alter a
    step's arithmetic; ``RESTART_KEYS``). ``physics``: part of the run's
    physics: summary.json lists it under "physics", and runs that differ in
    it are never one parameter set (``PHYSICS_KEYS``). ``param``: its column
    (1, 2, ...) among the keys that name a parameter set (summary.json
    "params", the columns of collect's runs.csv and sets.csv; ``PARAM_KEYS``),
    0 for none. A key without flags is physics fixed for the whole run.
    """
    section: str
    name: str
    default: object
    doc: str
    kind: type = float
    choices: tuple = ()
    restart: bool = False
    physics: bool = True
    param: int = 0


def _k(section, name, default, doc, kind=float, choices=(), *, restart=False, physics=True, param=0):
    return Key(section, name, default, doc, kind, choices, restart, physics, param)


SCHEMA = (
    _k("run", "max_steps", REQUIRED,
       "hard cap on time steps (required); a run that hits it is 'not converged'", int, restart=True, physics=False),
    _k("run", "seed", 1, "random seed of bed, insertion and initial velocities", int, physics=False, param=11),
    _k("run", "initial_file", "",
       "start from this configuration instead of building one: an mpdem HDF5 state file, a run's packing.npz "
       "(at rest, no contact histories: contact.mu = 0 only), a text table `id x y z [vx vy vz] [omegax omegay "
       "omegaz] [fixed]` (a header line names the columns), or a LAMMPS data file (atom_style sphere) or text "
       "dump (recognised by their content); the file's box and mobile count are the run's box.L_x, box.L_y and "
       "pour.N (taken where not given, refused where given and different; a text table keeps no box)", str,
       physics=False),
    _k("run", "fixed_types", (),
       "atom types of the bed (frozen) spheres in a LAMMPS initial_file, e.g. [2]; required for one",
       tuple, physics=False),
    _k("box", "L_x", 20.0, "periodic box length in x [d]", param=12),
    _k("box", "L_y", 20.0, "periodic box length in y [d]", param=13),
    _k("box", "gravity", 1.0, "gravitational acceleration [g]; 1 in reduced units, 0 only for verification runs"),
    _k("box", "incline", 0.0,
       "tilt of the pile about the y axis [degrees]: gravity g (sin theta, 0, -cos theta), x downslope; the bed "
       "and bed.wall stay at z = 0 (a chute in its own frame)"),
    _k("pour", "N", 20000, "number of mobile spheres", int, param=9),
    _k("pour", "phi_i", 0.13, "initial packing fraction of the random insertion (docs/model.md 5.3)", param=8),
    _k("pour", "K0", 0.0, "initial mean translational kinetic energy per particle [m g d]; 0 = at rest", param=10),
    _k("pour", "insertion", "whole",
       "how the pour's spheres are placed (docs/model.md 5.3): 'whole' (one random sequential addition over the "
       "whole insertion region, made by every rank alike: the paper's) or 'tiles' (the region cut into tiles of "
       "about pour.tile d, each filled on its own from its own random stream with gaps of d/2 at the faces "
       "between tiles; each rank fills its share of the tiles and holds only its rows, so a pour of many "
       "millions of spheres starts on many ranks; other centres, so other bits)", str, ("whole", "tiles")),
    _k("pour", "tile", 20.0, "the edge of a tiled pour's tiles at least [d] (pour.insertion = 'tiles'; an axis "
       "shorter than it is one tile)"),
    _k("contact", "model", "hooke", "normal/tangential force law: hooke or hertz (kernels/models.py)", str,
       tuple(MODELS), param=7),
    _k("contact", "k_n", 2e5, "normal spring constant [m g / d]", param=3),
    _k("contact", "k_t", DERIVED, "tangential spring constant [m g / d]; default 2 k_n / 7", param=4),
    _k("contact", "epsilon", 0.88, "coefficient of restitution of a free pair; sets gamma_n (eq. 4-5)", param=2),
    _k("contact", "gamma_n", DERIVED, "normal damping [sqrt(g/d)]; default from epsilon and k_n", param=5),
    _k("contact", "gamma_t", 0.0,
       "tangential damping [sqrt(g/d)]; 0 as in the method, gamma_n/2 the documented alternative", param=6),
    _k("contact", "mu", 0.5, "Coulomb friction coefficient (0 = frictionless)", param=1),
    _k("contact", "limit_damping", False, "clip an attractive normal force to 0 (off in the reference model)", bool),
    _k("contact", "history", "project",
       "tangential history update: project onto the tangent plane, or project and rescale to keep |Delta s|",
       str, ("project", "rotate")),
    _k("bed", "seed", -1,
       "random seed of the bed (-1: run.seed); set apart from run.seed, beds and pours are sampled apart (two runs "
       "of one run.seed on two beds are two samples)", int, physics=False),
    _k("bed", "file", "",
       "read the bed (frozen spheres) from this text table or HDF5 file instead of building it", str),
    _k("bed", "wall", False,
       "a plane at z = 0 under the bed with the pile's contact law and a tangential history of its own "
       "(LAMMPS wall/gran hooke/history zplane 0): a backstop under a sparse bed; without it a mobile sphere"
       " below the bed is an error", bool),
    _k("bed", "thickness", 1.0,
       "thickness of the slab cut from the settled packing [d]; docs/model.md 5.2 says 1.2, which holds "
       "~1.34 per d^2 of a dense packing, above the 1.0-1.3 check"),
    _k("bed", "gap", 4.0,
       "height of the cut slab's bottom above the temporary floor [d] (>= 2; the floor layers the packing up"
       " to ~3 d)"),
    _k("bed", "settle_density", 8.0, "spheres settled per unit floor area to make the bed [1/d^2]"),
    _k("bed", "settle_k_n", 2e3, "spring constant of the bed-making settle [m g / d]"),
    _k("bed", "settle_epsilon", 0.1, "restitution of the bed-making settle"),
    _k("bed", "settle_time", 40.0, "simulated time of the bed-making settle [tau]"),
    _k("bed", "density_min", 1.0, "warn if the bed's areal density is below this [1/d^2]"),
    _k("bed", "density_max", 1.3, "warn if the bed's areal density is above this [1/d^2]"),
    _k("integration", "dt", DERIVED, "time step [tau]; default 1e-4 sqrt(2e5 / k_n)", param=14),
    _k("integration", "skin", 0.2,
       "Verlet neighbour-list skin [d]; lists are rebuilt when a particle moved skin/2", physics=False),
    _k("integration", "near_skin", 0.03,
       "the force kernel's reach beyond contact [d] (<= skin; no effect on results): the list entries"
       " within 1 + near_skin, filtered again when a particle moved near_skin/2", physics=False),
    _k("stiffen", "k_n_from", 0.0,
       "stiffen a settled pile (docs/model.md 6.6): the k_n [m g / d] that run.initial_file was settled at, from "
       "which k_n rises geometrically to contact.k_n over stiffen.ramp_time (k_t, gamma_n from epsilon and "
       "gamma_t following, each Delta s rescaled by k_t old / new), after which the stop rule runs; at most a "
       "decade a rung; 0 = no ramp (`mpdem stiffen RUN --k_n K` sets it)"),
    _k("stiffen", "ramp_time", 10.0, "duration of the stiffening ramp [tau]"),
    _k("stiffen", "update_interval", 0.01,
       "the ramp's law changes this often [tau] (rounded to whole steps; between changes a GPU runs its steps "
       "in one launch)"),
    _k("flow", "incline", 0.0,
       "flow arrest (docs/model.md 5.5): the incline [degrees] of a flow phase from the run's first step for "
       "flow.time, gravity tilted as box.incline tilts it; then box.incline (the arrest angle, below the angle "
       "where flow stops) and the stop rule from there; 0 = no flow phase"),
    _k("flow", "time", 0.0, "duration of the flow phase [tau] (rounded to whole steps); > 0 with flow.incline; "
       "a restart inside the flow may change it (`restart RUN --set flow.time=T`, T past the restart's step)"),
    _k("stop", "E_stop", DERIVED,
       "stop when kinetic energy per particle is below this [m g d]; default 1e-8 (k_n/2e5)^(-3/4)", restart=True),
    _k("stop", "force_ratio", 0.01,
       "threshold of stop.rule = 'force': the unbalanced-force ratio (mean |resultant force| on the mobile "
       "spheres over mean |contact force|) below which the pile counts as static", restart=True),
    _k("stop", "rule", "window",
       "'window': mean E_k over the last `window` tau below E_stop; 'instantaneous': one sample below E_stop; "
       "'force': one sample's unbalanced-force ratio below stop.force_ratio with every mobile sphere in "
       "contact",
       str, ("window", "instantaneous", "force"), restart=True),
    _k("stop", "energy", "total",
       "the kinetic energy the rule tests: 'total' (translational + rotational, the paper's) or "
       "'translational' (a settled pile can keep a sphere spinning about the line through two contacts, "
       "which nothing in the contact model damps: docs/model.md 5.4)", str, ("total", "translational"), restart=True),
    _k("stop", "window", 1.0, "averaging window of the stop rule [tau]", restart=True),
    _k("stop", "sample_interval", 0.1,
       "kinetic-energy sampling interval [tau] (also the thermo table's)", restart=True),
    _k("checks", "overlap_warn", 0.05,
       "warn when an overlap exceeds this [d]; an initial table's overlaps up to this are accepted with one "
       "warning (a settled pile), deeper ones refused", restart=True, physics=False),
    _k("checks", "overlap_error", 0.3,
       "stop with an error when an overlap exceeds this [d]", restart=True, physics=False),
    _k("checks", "escape_margin", 100.0,
       "warn when a particle rises this far above the insertion region [d]", restart=True, physics=False),
    _k("engine", "device", "cpu",
       "what steps the particles: 'cpu' (numba threads) or 'gpu' (one NVIDIA GPU per rank through numba-cuda; "
       "`pip install .[gpu]`); the same bits either way, so a restart may change it", str, ("cpu", "gpu"),
       restart=True, physics=False),
    _k("engine", "gpu_block", 256,
       "threads per block of the GPU engine's kernels (a power of two from 32 to 1024); no effect on results",
       int, restart=True, physics=False),
    _k("engine", "gpu_threads", "row",
       "how the GPU engine's contact forces take its threads: 'row' (a thread a particle computes and sums its "
       "neighbour list's contacts) or 'entry' (a thread a list entry computes one contact, then a thread a "
       "particle sums its own in list order: more threads, the forces through GPU memory) or 'lanes2', 'lanes4', "
       "'lanes8', 'lanes16' (in the launches of many steps, with engine.gpu_pinned: that many threads of a warp a "
       "particle compute its contacts a round at a time and sum them in list order through warp shuffles); no "
       "effect on results", str, ("row", "entry", "lanes2", "lanes4", "lanes8", "lanes16"), restart=True,
       physics=False),
    _k("engine", "gpu_max_registers", 0,
       "registers a thread at most for the GPU engine's step kernels (ptxas's -maxrregcount: more resident "
       "blocks, perhaps spills); 0 = the compiler's choice, else 32 to 255; no effect on results",
       int, restart=True, physics=False),
    _k("engine", "gpu_reductions", "fused",
       "the GPU engine's fused steps' block reductions: 'tree' (a tree of barriers a value) or 'fused' (a phase's "
       "values in one tree: fewer than half the barriers) or 'warp' (in the launches of many steps, with "
       "engine.gpu_pinned: a phase's values by warp shuffles, two block barriers); no effect on results", str,
       ("tree", "fused", "warp"), restart=True, physics=False),
    _k("engine", "gpu_samples", "device",
       "where the GPU engine sums the stop rule's samples (kinetic energy, force ratio): 'host' (the rows and the "
       "entries' forces copied to the host) or 'device' (the same exact fixed-point sums by integer atomics on the "
       "GPU, a few kB copied); no effect on results", str, ("host", "device"), restart=True, physics=False),
    _k("engine", "gpu_drift", "fused",
       "where the GPU engine's launches of many steps do the next step's half-kicks and drift: 'apart' (a phase of "
       "its own: two grid barriers a step) or 'fused' (by the thread that has just summed the particle's forces, the "
       "rows in two buffers: one grid barrier a step fewer); no effect on results", str, ("apart", "fused"),
       restart=True, physics=False),
    _k("engine", "gpu_pinned", True,
       "compile the GPU engine's launches of many steps for the run's own options (the contact model, friction or "
       "none, limit_damping, rescale_history, the other engine.gpu_* choices) as constants, so that the compiler "
       "drops the code the run never takes; false = one kernel for every option; no effect on results", bool,
       restart=True, physics=False),
    _k("engine", "gpu_rebuild", "launch",
       "how the GPU engine sizes a list rebuild it makes on the GPU (one rank): 'host' (the host reads the "
       "particles' height range and the lists' length back and allocates the lists: two round trips) or 'device' "
       "(the cell grid and the lists into preallocated room on the GPU, no round trip; an overflow, flagged on the "
       "GPU and read with the next forces, builds them again with more room) or 'launch' (as 'device', and the "
       "launches of many steps rebuild the lists themselves, as phases of the launch, with either "
       "engine.gpu_threads); no effect on results", str, ("host", "device", "launch"), restart=True,
       physics=False),
    _k("engine", "gpu_sort", "host",
       "where the GPU engine orders the particles by cell (neighbours near in memory) at every 20th list rebuild on "
       "one rank: 'host' (rows and contact history copied down, sorted and the lists built there, all copied back) "
       "or 'device' (a counting sort by the same cells on the GPU, the rows permuted and the history carried by "
       "partner id there, the permutation copied back); no effect on results", str, ("host", "device"),
       restart=True, physics=False),
    _k("engine", "gpu_exchange", "host",
       "how the GPU engine on several ranks exchanges particles with the other ranks: 'host' (at a list rebuild "
       "every row and its contact history copied down, the migration, the ghosts and the lists made there, all "
       "copied back; at every step the ghosts' sources gathered on the GPU, sent from the host's rows, the ghosts "
       "copied up field by field) or 'device' (at a rebuild the positions copied down, the particles that leave "
       "or are sent as ghosts brought down with their history as they go, the arrivals and the ghosts copied up, "
       "the rows placed, the lists built and the history carried by partner id on the GPU; at every step the "
       "messages packed and unpacked on the GPU, one copy each way); no effect on results",
       str, ("host", "device"), restart=True, physics=False),
    _k("decomp", "grid", (),
       "the ranks' grid of domains [Px, Py, Pz]: Px x Py columns of equal widths in x and y, each cut into Pz "
       "slabs along z that balance its work (the product is the number of ranks); [] = chosen from the ranks, "
       "the box and the pile's height (the least halo a rank: a tall narrow pile stays all slabs [1, 1, P], a "
       "wide low one gets columns); no effect on results", tuple, restart=True, physics=False),
    _k("decomp", "balance_by", "work",
       "what the slabs balance over the ranks: 'work' (each rank's compute seconds since the last list "
       "rebuild, the communication left out) or 'count' (owned mobile particles); no effect on results",
       str, ("work", "count"), restart=True, physics=False),
    _k("decomp", "balance_tolerance", 0.1,
       "rebalance the slabs at a list rebuild when max/mean over the ranks of what they balance > 1 + this",
       restart=True, physics=False),
    _k("decomp", "balance_every", 500,
       "with balance_by = 'work': steps since the last list rebuild between checks of the ranks' work (one small "
       "collective); an uneven one (decomp.balance_tolerance, once the slowest rank measured decomp.balance_seconds) "
       "rebuilds the "
       "lists there to rebalance, where a settled pile may not rebuild for thousands of steps; 0 = rebalance only at "
       "the rebuilds the particles' motion calls for; no effect on results", int, restart=True, physics=False),
    _k("decomp", "balance_seconds", 0.5,
       "compute seconds the slowest rank has measured at least before a check of decomp.balance_every may "
       "rebalance (less is mostly the clock's noise) [s]", restart=True, physics=False),
    _k("decomp", "balance_damping", 0.5,
       "fraction of the way the slab bounds move toward balance at a rebalance", restart=True, physics=False),
    _k("output", "progress_every", 10000, "steps between progress lines", int, restart=True, physics=False),
    _k("output", "checkpoint_every", 0,
       "steps between checkpoints (RUN/checkpoints/ckpt-NNNNN.h5); 0 = none on a step schedule",
       int, restart=True, physics=False),
    _k("output", "checkpoint_seconds", 1800.0,
       "wall-clock seconds between checkpoints; 0 = none on a clock schedule", restart=True, physics=False),
    _k("output", "checkpoint_keep", 3,
       "newest checkpoints kept; older ones are deleted", int, restart=True, physics=False),
    _k("output", "snapshot_every", 0,
       "steps between snapshots for analysis (RUN/snapshots/snap-NNNNN.h5 with an XDMF sidecar); 0 = only "
       "the final state", int, restart=True, physics=False),
    _k("output", "bulk_at_end", True,
       "measure the bulk (z, phi) at the run's end for summary.json, each rank on its own spheres and ghosts "
       "with exact sums over the ranks (the same bits on any ranks and grid; some 200 bytes a contact of the "
       "rank's rows for the time it takes); false: no bulk measurement in the summary (`mpdem analyze RUN` makes "
       "it from final.h5 later)", bool, restart=True,
       physics=False),
    _k("analysis", "margin_bottom", -1.0,
       "bulk margin above the bed [d]; -1 = 10 for a pile at least analysis.tall_pile high, else clamp(0.2 "
       "(h - z_bed), 3, 10)", restart=True, physics=False),
    _k("analysis", "margin_top", -1.0,
       "bulk margin below the free surface [d]; -1 = as margin_bottom", restart=True, physics=False),
    _k("analysis", "rattlers", "force",
       "rattler rule: 'force' (the backbone: contacts below analysis.force_fraction of their depth band's "
       "mean normal force dropped, then, repeatedly, spheres that cannot balance their weight with the "
       "contacts left; docs/model.md 6.2) or 'count' (fewer than analysis.n_min contacts, the rule of "
       "packings without gravity)", str, ("force", "count"), restart=True, physics=False),
    _k("analysis", "force_fraction", 0.01,
       "the backbone's force cut: a contact whose normal force is below this fraction of the mean of its "
       "depth band carries no load", restart=True, physics=False),
    _k("analysis", "backbone_cuts", (0.001, 0.01, 0.05),
       "force cuts (fractions of the depth band's mean normal force) at which the backbone's z is also reported "
       "(docs/model.md 6.10)", list, restart=True, physics=False),
    _k("analysis", "band_width", 2.5,
       "depth bands below the free surface of the depth profile, P(f) and the backbone's force cut [d]",
       restart=True, physics=False),
    _k("analysis", "n_min", -1,
       "threshold of the count rule (analysis.rattlers = 'count', also reported beside the backbone): fewer "
       "contacts are removed; -1 = 4 for mu = 0, 2 for mu > 0", int, restart=True, physics=False),
    _k("analysis", "profile_bin", 0.5, "bin width of the phi(z) profile [d]", restart=True, physics=False),
    _k("analysis", "tall_pile", 40.0,
       "pile height h - z_bed [d] from which the automatic margins are the paper's 10 d (docs/model.md 6.1)",
       restart=True, physics=False),
    _k("analysis", "g_dr", 0.01, "bin width of the full g(r) [d]", restart=True, physics=False),
    _k("analysis", "g_r_max", 5.0, "range of the full g(r) [d]; below half the box", restart=True, physics=False),
    _k("analysis", "near_r_max", 1.5,
       "range of the near-contact g(r) [d] (a thinner excluded shell, more reference particles)",
       restart=True, physics=False),
    _k("analysis", "xi_min", 1e-6,
       "smallest xi = r/d - 1 of the logarithmic near-contact bins", restart=True, physics=False),
    _k("analysis", "xi_per_decade", 10,
       "logarithmic bins per decade of xi (they run from xi_min to 1)", int, restart=True, physics=False),
    _k("analysis", "fit_xi_hi", 5e-2,
       "upper end of the power-law fit window in xi (eq. 6)", restart=True, physics=False),
    _k("analysis", "fit_xi_lo", 1e-3,
       "lower end of the default alpha window in xi, the same for every k_n and mu (-1, from older configs, "
       "means 1e-3)", restart=True, physics=False),
    _k("analysis", "alpha_windows", (1e-3, 1e-2, 5e-2),
       "edges of the alpha windows reported side by side: each [e_i, e_i+1] and the whole [e_0, e_last] "
       "(docs/model.md 6.5)", list, restart=True, physics=False),
    _k("analysis", "depth_windows", (10.0, 30.0, 5.0, 15.0, 15.0, 25.0),
       "fixed windows of depth below the free surface h [d], as pairs (top, bottom): [10, 30, 5, 15] is "
       "10-30 d and 5-15 d; z, phi and alpha on each, with jackknife errors (docs/model.md 6.10)",
       list, restart=True, physics=False),
    _k("analysis", "jackknife_columns", 4,
       "lateral columns along x and along y of the jackknife errors (k x k columns, k >= 2; docs/model.md 6.10)",
       int, restart=True, physics=False),
    _k("analysis", "surface_cell", 2.0,
       "side of the cells on which the free surface's height field is taken [d] (the box split into "
       "round(L / surface_cell) cells per axis): its roughness and rms local slopes (docs/model.md 6.10)",
       restart=True, physics=False),
    _k("analysis", "steady_window", 100.0,
       "a flow-arrest run's flow counts as steady when the mean v_x and E_k of thermo.csv change by less than "
       "analysis.steady_tolerance between the two halves of this last span of the flow phase [tau] "
       "(docs/model.md 5.5)", restart=True, physics=False),
    _k("analysis", "steady_tolerance", 0.02,
       "the largest relative change between the halves of analysis.steady_window", restart=True, physics=False),
    _k("analysis", "flow_v_min", 0.01,
       "a state counts as flowing, and its v_x(z) is fitted to the Bagnold profile (summary flow.bagnold), when "
       "the mean v_x of its mobile spheres exceeds this [sqrt(g d)]", restart=True, physics=False),
    _k("analysis", "zeta_bins", 50,
       "bins of P(zeta) on [0, 1], zeta = |F_t| / (mu F_n)", int, restart=True, physics=False),
    _k("analysis", "mobilised", 0.99,
       "zeta above which a contact counts as fully mobilised", restart=True, physics=False),
    _k("analysis", "figure_format", "png",
       "formats of the figures of analyze and collect: png, pdf or svg, several joined by commas "
       "(e.g. png,pdf)", str, restart=True, physics=False),
    _k("analysis", "order_cutoff", 1.4, "neighbour shell of the q6 bond order [d]", restart=True, physics=False),
    _k("analysis", "order_bond", 0.7,
       "normalised q6 product above which a bond is solid-like", restart=True, physics=False),
    _k("analysis", "order_bonds", 8,
       "solid-like bonds that make a sphere crystal-like", int, restart=True, physics=False),
)

# keys that no longer exist: older configs and state files that carry them still load (the key is
# left out); a --set of one is refused with the reason
RETIRED = {"integration.contact_slots": "unused since the contact history moved to the neighbour lists"}

SECTIONS = tuple(dict.fromkeys(k.section for k in SCHEMA))
KEYS = MappingProxyType({f"{k.section}.{k.name}": k for k in SCHEMA})
# the flags of SCHEMA as tuples of 'section.key' names (schema order; PARAM_KEYS in column order)
# the largest rise of one stiffening rung, k_n / stiffen.k_n_from: a decade (docs/model.md 6.6); 1e-12 for the
# rounding of the quotient
MAX_RISE = 10.0 * (1.0 + 1e-12)


def bed_seed(cfg):
    """The seed of the bed's random stream: ``bed.seed``, or ``run.seed`` where it is -1."""
    return cfg.bed.seed if cfg.bed.seed >= 0 else cfg.run.seed


RESTART_KEYS = tuple(name for name, k in KEYS.items() if k.restart)
PHYSICS_KEYS = tuple(name for name, k in KEYS.items() if k.physics)
PARAM_KEYS = tuple(sorted((name for name, k in KEYS.items() if k.param), key=lambda name: KEYS[name].param))


def key_summary(names):
    """'run.max_steps, stop.*, ...': ``names`` (schema order) with a whole section as 'section.*'."""
    names, out = set(names), []
    for sec in SECTIONS:
        keys = [n for n in KEYS if n.startswith(sec + ".")]
        if all(n in names for n in keys):
            out.append(f"{sec}.*")
        else:
            out += [n for n in keys if n in names]
    return ", ".join(out)


def gamma_n_from_epsilon(epsilon, k_n, m_eff=0.5):
    """Normal damping giving restitution ``epsilon`` for a free pair (eq. 4-5).

    gamma_n = 2 L sqrt(2 k_n / m) / sqrt(pi^2 + L^2), L = -ln(epsilon), m = 1.
    ``m_eff`` is the reduced mass of the pair (1/2 for two free spheres).
    """
    lg = -math.log(epsilon)
    return 2.0 * lg * math.sqrt(k_n / m_eff) / math.sqrt(math.pi ** 2 + lg ** 2)


def restitution(gamma_n, k_n, m_eff=0.5):
    """Restitution of a head-on collision with reduced mass ``m_eff`` (eq. 4)."""
    return math.exp(-math.pi * gamma_n / (2.0 * math.sqrt(k_n / m_eff - gamma_n ** 2 / 4.0)))


def collision_time(gamma_n, k_n, m_eff=0.5):
    """Duration of a head-on Hookean collision [tau] (eq. 5)."""
    return math.pi / math.sqrt(k_n / m_eff - gamma_n ** 2 / 4.0)


@dataclass(frozen=True)
class Config:
    """Resolved configuration: ``values['section.key']`` for every key.

    Attribute access by section: ``cfg.contact.k_n``.
    """
    values: MappingProxyType
    warnings: tuple = ()
    derived: frozenset = field(default_factory=frozenset)
    # the keys the user gave (config file, --set), as opposed to defaults
    given: frozenset = field(default_factory=frozenset)

    def __getattr__(self, section):
        # called only when the section is not yet cached on the instance
        if section not in SECTIONS:
            raise AttributeError(section)
        vals = {k.split(".", 1)[1]: v for k, v in self.values.items()
                if k.startswith(section + ".")}
        sec = _Section(section, vals)
        # built once: later lookups find it in the instance dict (frozen, hence object.__setattr__)
        object.__setattr__(self, section, sec)
        return sec

    def replace(self, **updates):
        """A new Config with ``{'section.key': value}`` overrides, re-resolved."""
        raw = {k: v for k, v in self.values.items() if k not in self.derived}
        raw.update(updates)
        new = resolve(raw)
        object.__setattr__(new, "given", self.given | frozenset(updates))
        return new

    def to_toml(self):
        """Every key with its value; derived defaults are marked."""
        lines = ["# mpdem resolved configuration (every default filled in)"]
        for sec in SECTIONS:
            lines.append(f"\n[{sec}]")
            for k in SCHEMA:
                if k.section != sec:
                    continue
                name = f"{sec}.{k.name}"
                text = f"{k.name} = {toml_value(self.values[name])}"
                if name in self.derived:
                    text += "  # derived default"
                lines.append(text)
        return "\n".join(lines) + "\n"


class _Section:
    """The keys of one config section as read-only attributes (shared by every access)."""

    def __init__(self, name, vals):
        self.__dict__["_name"] = name
        self.__dict__.update(vals)

    def __setattr__(self, name, value):
        raise AttributeError(f"config section [{self._name}] is read-only")

    __delattr__ = __setattr__

    def __repr__(self):
        return f"<{self._name} {self.__dict__}>"


def toml_value(v):
    """A value as TOML text (lists and tuples as arrays)."""
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(toml_value(a) for a in v) + "]"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def did_you_mean(name, known):
    """' (did you mean X?)' for the known name nearest to ``name``, or '' when none is near.

    ``known`` are full ``section.key`` names or section names; a key is also
    matched by its part after the dot (``kn`` finds ``contact.k_n``).
    """
    import difflib
    known = list(known)
    if "." in name:     # the right name in another section (``[contact] max_steps``: run.max_steps)
        sec, tail = name.split(".", 1)
        near = difflib.get_close_matches(name, [k for k in known if k.startswith(sec + ".")], n=1, cutoff=0.8)
        same = [k for k in known if "." in k and k.split(".", 1)[1] == tail and k != name]
        if same and not near:
            return f" (did you mean {same[0]}?)"
    hit = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    if not hit and "." not in name:
        tails = {k.split(".", 1)[1]: k for k in known if "." in k}
        hit = [tails[t] for t in difflib.get_close_matches(name, list(tails), n=1, cutoff=0.6)]
    if not hit and "." in name:
        tails = {k.split(".", 1)[1]: k for k in known if "." in k}
        hit = [tails[t] for t in difflib.get_close_matches(name.split(".", 1)[1], list(tails), n=1, cutoff=0.75)]
    return f" (did you mean {hit[0]}?)" if hit else ""


def flatten(doc, origin="config"):
    """{'section': {'key': v}} -> {'section.key': v}, rejecting unknown names."""
    flat = {}
    for sec, body in doc.items():
        if sec not in SECTIONS or not isinstance(body, dict):
            raise ConfigError(f"{origin}: unknown section [{sec}]{did_you_mean(str(sec), SECTIONS)}; "
                              f"known sections: {', '.join(SECTIONS)}")
        for name, v in body.items():
            key = f"{sec}.{name}"
            if key in RETIRED:
                continue
            if key not in KEYS:
                known = ", ".join(k.name for k in SCHEMA if k.section == sec)
                raise ConfigError(f"{origin}: unknown key {key}{did_you_mean(key, KEYS)}; keys of [{sec}]: {known}")
            flat[key] = v
    return flat


def raw_from_toml(text, origin="config"):
    """The flat keys of a ``Config.to_toml`` text, less those marked "# derived default".

    Resolving the result derives those keys again (the same values), so the
    Config knows them as derived and its ``to_toml`` gives back the same text.
    """
    raw = flatten(tomllib.loads(text), origin=origin)
    section, derived = None, set()
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("[") and line.endswith("]"):
            section = line[1:-1].strip()
        elif line.endswith("# derived default") and "=" in line and section:
            derived.add(f"{section}.{line.split('=', 1)[0].strip()}")
    return {k: v for k, v in raw.items() if k not in derived}


def parse_set(item):
    """'section.key=value' -> ('section.key', value); value parsed as TOML if it can be."""
    if "=" not in item:
        raise ConfigError(f"--set {item!r}: expected section.key=value (with '=', no space: "
                          f"--set contact.mu=0.3)")
    key, text = (s.strip() for s in item.split("=", 1))
    if key in RETIRED:
        raise ConfigError(f"--set {key}: the key is retired ({RETIRED[key]})")
    if key not in KEYS:
        raise ConfigError(f"--set {key}: unknown key{did_you_mean(key, KEYS)}; {_known_near(key)}")
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text
    return key, value


def _known_near(key):
    """The keys of ``key``'s section, or the sections when it names none: what an unknown key's error lists."""
    sec = key.split(".", 1)[0] if "." in key else ""
    if sec in SECTIONS:
        return f"keys of [{sec}]: {', '.join(k.name for k in SCHEMA if k.section == sec)}"
    return f"keys are section.key, the sections: {', '.join(SECTIONS)}"


def load(path=None, sets=(), base=None):
    """Read a TOML file (or start from ``base``), apply ``--set`` items, resolve."""
    # the items first: a malformed one (``--set contact.mu -0.3``) is named as such, not as the config file
    parsed = [parse_set(item) for item in sets]
    raw = dict(base or {})
    if path is not None:
        try:
            with open(path, "rb") as fh:
                doc = tomllib.load(fh)
        except OSError as e:
            raise ConfigError(f"config file {path}: {e.strerror}") from None
        except tomllib.TOMLDecodeError as e:
            raise ConfigError(f"config file {path}: not valid TOML: {e}") from None
        raw.update(flatten(doc, origin=str(path)))
    raw.update(parsed)
    return resolve(raw)


def load_run_config(path=None, sets=()):
    """The config of ``mpdem run``: the TOML file ``path``, or the built-in example without it."""
    if path is not None:
        return load(path, sets)
    from importlib import resources
    text = resources.files("mpdem").joinpath("example.toml").read_text()
    cfg = load(None, sets, base=flatten(tomllib.loads(text), origin="built-in example"))
    # the example's values are its defaults: only --set keys count as given
    object.__setattr__(cfg, "given", frozenset(parse_set(item)[0] for item in sets))
    return cfg


def _coerce(key, value):
    spec = KEYS[key]
    if spec.kind is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key} = {value!r}: expected true or false")
        return value
    if spec.kind is int:
        if isinstance(value, bool) or not (isinstance(value, int) or
                                           (isinstance(value, float) and value.is_integer())):
            raise ConfigError(f"{key} = {value!r}: expected an integer")
        return int(value)
    if spec.kind is tuple:
        # a list of positive integers (atom types)
        if not isinstance(value, (list, tuple)) or any(
                isinstance(a, bool) or not isinstance(a, int) or a < 1 for a in value):
            raise ConfigError(f"{key} = {value!r}: expected a list of integers >= 1, e.g. [2]")
        return tuple(int(a) for a in value)
    if spec.kind is list:
        # a list of numbers
        if not isinstance(value, (list, tuple)) or not value or any(
                isinstance(a, bool) or not isinstance(a, (int, float)) or not math.isfinite(a) for a in value):
            raise ConfigError(f"{key} = {value!r}: expected a list of numbers, e.g. [1e-3, 1e-2]")
        return tuple(float(a) for a in value)
    if spec.kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key} = {value!r}: expected a number")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{key} = {value!r}: must be finite")
        return value
    if not isinstance(value, str):
        raise ConfigError(f"{key} = {value!r}: expected a string")
    if spec.choices and value not in spec.choices:
        raise ConfigError(f"{key} = {value!r}: accepted values are {', '.join(map(repr, spec.choices))}")
    return value


def resolve(raw):
    """Fill defaults, derive, validate. Returns a Config or raises ConfigError."""
    vals, derived, warns = {}, set(), []
    for key, spec in KEYS.items():
        if key in raw:
            vals[key] = _coerce(key, raw[key])
        elif spec.default is REQUIRED:
            raise ConfigError(f"{key} is required (no default); set it in the config or with --set {key}=...")
        elif spec.default is DERIVED:
            vals[key] = None
        else:
            vals[key] = spec.default

    def need(key, ok, accepted):
        if not ok:
            raise ConfigError(f"{key} = {vals[key]!r}: accepted {accepted}")

    block = vals["engine.gpu_block"]
    need("engine.gpu_block", 32 <= block <= 1024 and block & (block - 1) == 0, "a power of two from 32 to 1024")
    need("engine.gpu_threads", not (vals["engine.gpu_threads"].startswith("lanes") and not vals["engine.gpu_pinned"]),
         "'row' or 'entry' with engine.gpu_pinned = false (the lanes are compiled only into the pinned launches)")
    need("engine.gpu_reductions", not (vals["engine.gpu_reductions"] == "warp" and not vals["engine.gpu_pinned"]),
         "'tree' or 'fused' with engine.gpu_pinned = false (the warps' reductions are compiled only into the pinned "
         "launches)")
    regs = vals["engine.gpu_max_registers"]
    need("engine.gpu_max_registers", regs == 0 or 32 <= regs <= 255, "0 (the compiler's choice) or 32 to 255")
    k_n = vals["contact.k_n"]
    need("contact.k_n", k_n > 0, "k_n > 0")
    if not 1e3 <= k_n <= 1e10:
        warns.append(f"contact.k_n = {k_n:g} is outside [1e3, 1e10] (paper: 2e5 to 2e9)")
    if vals["contact.k_t"] is None:
        vals["contact.k_t"] = 2.0 * k_n / 7.0
        derived.add("contact.k_t")
    need("contact.k_t", vals["contact.k_t"] >= 0, "k_t >= 0")
    if not math.isclose(vals["contact.k_t"], 2 * k_n / 7, rel_tol=1e-12):
        warns.append(f"contact.k_t = {vals['contact.k_t']:g} differs from 2 k_n / 7 = {2 * k_n / 7:g} "
                     f"(the paper's ratio)")
    eps = vals["contact.epsilon"]
    need("contact.epsilon", 0 < eps <= 1, "0 < epsilon <= 1")
    gcrit = 2.0 * math.sqrt(2.0 * k_n)
    if vals["contact.gamma_n"] is None:
        vals["contact.gamma_n"] = gamma_n_from_epsilon(eps, k_n)
        derived.add("contact.gamma_n")
    else:
        g = vals["contact.gamma_n"]
        need("contact.gamma_n", 0 <= g < gcrit, f"0 <= gamma_n < 2 sqrt(2 k_n / m) = {gcrit:.6g} (critical damping)")
        if "contact.epsilon" in raw:
            if not math.isclose(restitution(g, k_n), eps, rel_tol=1e-9, abs_tol=1e-12):
                raise ConfigError(f"contact.gamma_n = {g!r} and contact.epsilon = {eps!r} disagree "
                                  f"(gamma_n gives epsilon = {restitution(g, k_n):.6g}); give only one of them")
            # both given and agreeing (a run's own config.toml): epsilon stays as given, not as gamma_n's round
            # trip (0.5 -> 0.49999999999999994 at some k_n), so that a stiffening ramp's gamma_n, made from it,
            # is the same after a restart, and a family of runs keeps one epsilon
        else:
            vals["contact.epsilon"] = restitution(g, k_n)
            derived.add("contact.epsilon")
    gamma_n = vals["contact.gamma_n"]
    need("contact.gamma_t", vals["contact.gamma_t"] >= 0, "gamma_t >= 0")
    mu = vals["contact.mu"]
    need("contact.mu", 0 <= mu <= 1e4, "0 <= mu <= 1e4")
    if mu > 10:
        warns.append(f"contact.mu = {mu:g} is above the paper's range (0 to 10)")
    if MODELS[vals["contact.model"]].sqrt_overlap:
        warns.append(f"contact.model = {vals['contact.model']!r}: epsilon is nominal (velocity dependent); "
                     f"gamma_n is the Hookean value for it")

    phi = vals["pour.phi_i"]
    need("pour.phi_i", 0 < phi < 0.35, "0 < phi_i < 0.35 (random sequential addition fails near 0.38)")
    if phi > 0.30:
        warns.append(f"pour.phi_i = {phi:g} is above the paper's range (0.02 to 0.3)")
    need("pour.N", vals["pour.N"] >= 1, "N >= 1")
    need("pour.K0", vals["pour.K0"] >= 0, "K0 >= 0")
    if vals["pour.insertion"] == "tiles":
        need("pour.tile", vals["pour.tile"] >= 4, "tile >= 4 d (a tile's centres keep d/2 from its faces)")
    need("run.max_steps", vals["run.max_steps"] > 0, "max_steps > 0")
    need("run.seed", vals["run.seed"] >= 0, "seed >= 0")
    need("box.gravity", vals["box.gravity"] >= 0, "gravity >= 0 (it points along -z, tilted by box.incline)")
    need("box.incline", 0 <= vals["box.incline"] < 90, "0 <= incline < 90 degrees")

    skin = vals["integration.skin"]
    need("integration.skin", 0 < skin <= 1, "0 < skin <= 1 d")
    need("integration.near_skin", 0 < vals["integration.near_skin"] <= 1, "0 < near_skin <= 1 d")
    for key in ("box.L_x", "box.L_y"):
        need(key, vals[key] >= 3.0 and vals[key] >= 2 * (1.0 + skin),
             f"L >= 3 d and L >= 2 (d + skin) = {2 * (1 + skin):g} d (minimum image)")

    if vals["integration.dt"] is None:
        vals["integration.dt"] = 1e-4 * math.sqrt(2e5 / k_n)
        derived.add("integration.dt")
    dt = vals["integration.dt"]
    need("integration.dt", dt > 0, "dt > 0")
    t_col = collision_time(gamma_n, k_n)
    ratio = t_col / dt
    if ratio < 10:
        raise ConfigError(f"integration.dt = {dt:g}: t_col / dt = {ratio:.3g}; accepted t_col / dt >= 10 "
                          f"(t_col = {t_col:.4g}); default dt is 1e-4 sqrt(2e5 / k_n)")
    if ratio < 30:
        warns.append(f"integration.dt = {dt:g} resolves a collision with only {ratio:.1f} steps (30 or more advised)")
    if gamma_n * dt > 0.5:
        raise ConfigError(f"integration.dt = {dt:g}: gamma_n dt = {gamma_n * dt:.3g}; accepted gamma_n dt <= 0.5")

    k_from = vals["stiffen.k_n_from"]
    need("stiffen.k_n_from", k_from == 0 or k_from > 0 and 1 < k_n / k_from <= MAX_RISE,
         f"0 (no ramp) or a stiffness below contact.k_n = {k_n:g} by at most a decade (a rung; several rungs "
         f"for more)")
    need("stiffen.ramp_time", vals["stiffen.ramp_time"] > 0, "ramp_time > 0")
    need("stiffen.update_interval", 0 < vals["stiffen.update_interval"] <= vals["stiffen.ramp_time"],
         "0 < update_interval <= ramp_time")
    if k_from > 0 and not vals["run.initial_file"]:
        raise ConfigError(f"stiffen.k_n_from = {k_from:g} needs run.initial_file: the pile settled at that k_n")
    need("analysis.steady_window", vals["analysis.steady_window"] > 0, "steady_window > 0")
    need("analysis.steady_tolerance", vals["analysis.steady_tolerance"] > 0, "steady_tolerance > 0")
    need("analysis.flow_v_min", vals["analysis.flow_v_min"] > 0, "flow_v_min > 0")
    f_inc, f_time = vals["flow.incline"], vals["flow.time"]
    need("flow.incline", 0 <= f_inc < 90, "0 (no flow phase) <= incline < 90 degrees")
    need("flow.time", f_time >= 0 and (f_time > 0) == (f_inc > 0),
         "time > 0 with a flow phase (flow.incline > 0), 0 without")
    if f_inc > 0 and k_from > 0:
        raise ConfigError(f"flow.incline = {f_inc:g} with stiffen.k_n_from = {k_from:g}: a run takes a flow phase "
                          f"or a stiffening ramp, not both (stiffen the arrested pile in a run of its own)")
    if vals["stop.E_stop"] is None:
        vals["stop.E_stop"] = 1e-8 * (k_n / 2e5) ** -0.75
        derived.add("stop.E_stop")
    need("stop.E_stop", vals["stop.E_stop"] > 0, "E_stop > 0")
    need("stop.sample_interval", vals["stop.sample_interval"] > 0, "sample_interval > 0")
    need("stop.window", vals["stop.window"] >= vals["stop.sample_interval"], "window >= sample_interval")
    need("checks.overlap_warn", vals["checks.overlap_warn"] > 0, "overlap_warn > 0")
    need("checks.overlap_error", vals["checks.overlap_error"] > vals["checks.overlap_warn"],
         "overlap_error > overlap_warn")
    need("checks.escape_margin", vals["checks.escape_margin"] > 0, "escape_margin > 0")
    need("output.progress_every", vals["output.progress_every"] >= 1, "progress_every >= 1")
    for key in ("output.checkpoint_every", "output.checkpoint_seconds", "output.snapshot_every"):
        need(key, vals[key] >= 0, "0 (off) or a positive interval")
    need("output.checkpoint_keep", vals["output.checkpoint_keep"] >= 1, "checkpoint_keep >= 1")
    need("decomp.grid", len(vals["decomp.grid"]) in (0, 3), "[] (chosen) or three integers [Px, Py, Pz]")
    need("decomp.balance_tolerance", vals["decomp.balance_tolerance"] > 0, "balance_tolerance > 0")
    need("decomp.balance_every", vals["decomp.balance_every"] >= 0, "balance_every >= 0 (0 = at rebuilds only)")
    need("decomp.balance_seconds", vals["decomp.balance_seconds"] >= 0, "balance_seconds >= 0")
    need("decomp.balance_damping", 0 < vals["decomp.balance_damping"] <= 1, "0 < balance_damping <= 1")
    need("bed.seed", vals["bed.seed"] >= -1, "-1 (run.seed) or a seed >= 0")
    need("bed.thickness", vals["bed.thickness"] > 0, "thickness > 0")
    need("bed.gap", vals["bed.gap"] >= 0, "gap >= 0")
    need("bed.settle_density", 0 < vals["bed.settle_density"] <= 50, "0 < settle_density <= 50")
    need("bed.settle_k_n", vals["bed.settle_k_n"] > 0, "settle_k_n > 0")
    need("bed.settle_epsilon", 0 < vals["bed.settle_epsilon"] <= 1, "0 < settle_epsilon <= 1")
    need("bed.settle_time", vals["bed.settle_time"] > 0, "settle_time > 0")
    for key in ("analysis.margin_bottom", "analysis.margin_top"):
        need(key, vals[key] == -1 or vals[key] >= 0, "-1 (automatic) or a margin >= 0")
    need("analysis.n_min", vals["analysis.n_min"] == -1 or vals["analysis.n_min"] >= 0, "-1 (automatic) or n_min >= 0")
    need("analysis.profile_bin", vals["analysis.profile_bin"] > 0, "profile_bin > 0")
    need("analysis.tall_pile", vals["analysis.tall_pile"] > 0, "tall_pile > 0")
    need("analysis.g_r_max", vals["analysis.g_r_max"] > 1, "g_r_max > 1 (and below half the box)")
    need("analysis.g_dr", 0 < vals["analysis.g_dr"] < vals["analysis.g_r_max"], "0 < g_dr < g_r_max")
    need("analysis.near_r_max", vals["analysis.near_r_max"] > 1, "near_r_max > 1 (and below half the box)")
    need("analysis.xi_min", 0 < vals["analysis.xi_min"] < 1, "0 < xi_min < 1")
    need("analysis.xi_per_decade", vals["analysis.xi_per_decade"] >= 1, "xi_per_decade >= 1")
    need("analysis.fit_xi_hi", 0 < vals["analysis.fit_xi_hi"] <= 1, "0 < fit_xi_hi <= 1")
    lo = vals["analysis.fit_xi_lo"]
    need("analysis.fit_xi_lo", lo == -1 or 0 < lo < vals["analysis.fit_xi_hi"],
         "0 < fit_xi_lo < fit_xi_hi (or -1: 1e-3)")
    w = vals["analysis.alpha_windows"]
    need("analysis.alpha_windows", len(w) >= 2 and all(0 < a < b <= 1 for a, b in zip(w, w[1:])),
         "at least two increasing edges in (0, 1]")
    dw = vals["analysis.depth_windows"]
    need("analysis.depth_windows", len(dw) % 2 == 0 and all(0 <= t < b for t, b in zip(dw[::2], dw[1::2])),
         "pairs (top, bottom) of depths below the surface, 0 <= top < bottom")
    need("analysis.backbone_cuts", all(0 <= c < 1 for c in vals["analysis.backbone_cuts"]),
         "fractions 0 <= cut < 1")
    need("analysis.jackknife_columns", vals["analysis.jackknife_columns"] >= 2, "jackknife_columns >= 2")
    need("analysis.surface_cell", vals["analysis.surface_cell"] > 0, "surface_cell > 0 [d]")
    need("analysis.force_fraction", 0 <= vals["analysis.force_fraction"] < 1, "0 <= force_fraction < 1")
    need("analysis.band_width", vals["analysis.band_width"] > 0, "band_width > 0")
    need("stop.force_ratio", 0 < vals["stop.force_ratio"] < 1, "0 < force_ratio < 1")
    fmts = [f.strip().lower() for f in vals["analysis.figure_format"].split(",")]
    need("analysis.figure_format", bool(fmts) and all(f in ("png", "pdf", "svg") for f in fmts),
         "png, pdf or svg, several joined by commas")
    need("analysis.order_cutoff", 1 < vals["analysis.order_cutoff"] < 2, "1 < order_cutoff < 2")
    need("analysis.order_bond", -1 <= vals["analysis.order_bond"] < 1, "-1 <= order_bond < 1")
    need("analysis.order_bonds", vals["analysis.order_bonds"] >= 1, "order_bonds >= 1")
    need("analysis.zeta_bins", vals["analysis.zeta_bins"] >= 1, "zeta_bins >= 1")
    need("analysis.mobilised", 0 < vals["analysis.mobilised"] <= 1, "0 < mobilised <= 1")
    return Config(MappingProxyType(vals), tuple(warns), frozenset(derived), frozenset(raw))


def reference_markdown():
    """The config reference table of docs/config.md, generated from SCHEMA.

    Columns: key, default, the flags ``restart`` and ``physics`` (yes/no), meaning.
    """
    rows = ["| key | default | restart | physics | meaning |", "|---|---|---|---|---|"]
    for k in SCHEMA:
        d = ("required" if k.default is REQUIRED else "derived" if k.default is DERIVED
             else toml_value(k.default))
        doc = k.doc + (f" (one of {', '.join(k.choices)})" if k.choices else "")
        flags = " | ".join("yes" if f else "no" for f in (k.restart, k.physics))
        rows.append(f"| `{k.section}.{k.name}` | {d} | {flags} | {doc} |")
    return "\n".join(rows)


__all__ = ["Config", "ConfigError", "load", "resolve", "parse_set", "SCHEMA",
           "RESTART_KEYS", "PHYSICS_KEYS", "PARAM_KEYS", "key_summary",
           "gamma_n_from_epsilon", "restitution", "collision_time", "MAX_RISE", "bed_seed",
           "reference_markdown"]
