"""Helpers shared by the serial tests (imported as ``helpers``; fixtures stay in conftest)."""
import os
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np

from mpdem import config
from mpdem.io import tables
from mpdem.io import checkpoint
from mpdem.analysis import bulk
from mpdem.config import gamma_n_from_epsilon
from mpdem.decomp import Domain
from mpdem.engine.base import Physics
from mpdem.engine.cpu import Engine
from mpdem.state import State

ROOT = Path(__file__).resolve().parents[1]
MPIEXEC = Path(sys.executable).parent / "mpiexec"
# the variables of the job helper and the schedulers, which a child must not inherit by accident
CLUSTER_VARS = ("MPDEM_", "SLURM_", "PBS_")


def tight_lattice(seed=3, a=0.997, m=9):
    """A jittered m x m x m cubic lattice of spacing a, a little tighter than touching (some 3
    contacts a sphere from the start), lifted 0.5 d, with random v and omega and its lowest layer
    frozen (rows the force pass skips, partners of infinite mass).

    Returns x, v, omega (n, 3), fixed (n,) uint8 and the box side L = a m [d].
    """
    g = np.random.default_rng(seed)
    x = a * (np.stack(np.meshgrid(*(np.arange(m),) * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    x += 0.004 * g.standard_normal(x.shape)
    x[:, 2] += 0.5
    v = 0.05 * g.standard_normal(x.shape)
    omega = 0.1 * g.standard_normal(x.shape)
    return x, v, omega, (x[:, 2] < a).astype(np.uint8), a * m


def make_engine(x, v=None, omega=None, fixed=None, L=10.0, **phys):
    """An Engine over the given particles (ids 0..n-1) with set-up done."""
    k_n = phys.pop("k_n", 2e5)
    eps = phys.pop("epsilon", 0.88)
    defaults = dict(k_n=k_n, k_t=2 * k_n / 7, gamma_n=gamma_n_from_epsilon(eps, k_n),
                    gamma_t=0.0, mu=0.0, dt=1e-4 * np.sqrt(2e5 / k_n), gravity=0.0)
    defaults.update(phys)
    x = np.asarray(x, float)
    st = State(np.arange(len(x)), x, v, omega, fixed, L, L)
    eng = Engine(st, Physics.of(**defaults), Domain(None))
    eng.start()
    return eng


def settled_table(path, depth=1e-3):
    """A 6 d x 6 d bed (36 spheres on a unit grid at z = 0) with a column of
    6 mobile spheres on each, each sphere overlapping the one below by ``depth`` [d].

    Returns the numbers of mobile (216) and bed (36) spheres."""
    g = np.arange(6) + 0.5
    bed = np.array([[i, j, 0.0] for j in g for i in g])
    mob = np.array([[i, j, (1 - depth) * k] for k in range(1, 7) for j in g for i in g])
    x = np.concatenate([mob, bed])
    fixed = np.r_[np.zeros(len(mob)), np.ones(len(bed))].astype(np.uint8)
    tables.write_table(path, np.arange(1, len(x) + 1), x, fixed=fixed)
    return len(mob), len(bed)


def draw_gaps(rng, n, alpha, a, b):
    """n gaps from p(xi) ~ xi^-alpha (1 + xi)^2 on [a, b]: inverse transform of xi^-alpha, then rejection."""
    out = []
    while sum(map(len, out)) < n:
        u = rng.random(4 * n)
        e = 1.0 - alpha
        xi = (a ** e + u * (b ** e - a ** e)) ** (1.0 / e)
        keep = rng.random(xi.size) < ((1 + xi) / (1 + b)) ** 2
        out.append(xi[keep])
    return np.concatenate(out)[:n]


# nearest-neighbour distance of the crystals: a hair below d, so neighbours overlap (contact is delta > 0)
SQUEEZE = 1.0 - 1e-7


def fcc(cells_xy, cells_z, a):
    """FCC with cubic cell a, cells_xy^2 x cells_z cells; (n, 3) positions and the box side."""
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    g = np.array([[i, j, k] for k in range(cells_z) for j in range(cells_xy) for i in range(cells_xy)], float)
    x = ((g[:, None, :] + basis[None, :, :]).reshape(-1, 3) + 0.25) * a
    return x, cells_xy * a


def simple_cubic(nxy, nz, a):
    g = np.array([[i, j, k] for k in range(nz) for j in range(nxy) for i in range(nxy)], float)
    return (g + 0.5) * a, nxy * a


def write_crystal(path, x, fixed, L, sets=(), converged=False, step=7):
    """A state file of a hand-built packing, as a run would write it (at ``step``)."""
    n = len(x)
    cfg = config.load(None, ["run.max_steps=1", f"box.L_x={L}", f"box.L_y={L}",
                             f"pour.N={int((fixed == 0).sum())}"] + list(sets))
    a = {"id": np.arange(n), "x": x, "fixed": fixed.astype(np.uint8), "count": np.zeros(n, np.int64),
         "partner": np.zeros(0, np.int64), "ds": np.zeros((0, 3))}
    for f in ("v", "omega", "f", "torque"):
        a[f] = np.zeros((n, 3))
    pairs, r = bulk.find_contacts(x, L, L)
    F_n = cfg.contact.k_n * (1 - r)
    F_t = np.zeros((len(r), 3))
    F_t[:, 0] = 0.5 * cfg.contact.mu * F_n
    a.update(id_i=pairs[:, 0], id_j=pairs[:, 1], delta=1 - r, F_n=F_n, F_t=F_t, ds_i=np.zeros((len(r), 3)))
    checkpoint.write(str(path), a, {"kind": "snapshot", "step": step, "time": 0.1 * step, "n": n, "L_x": L, "L_y": L,
                                    "n_mobile": int((fixed == 0).sum()), "n_bed": int(fixed.sum()),
                                    "converged": converged, "config": cfg.to_toml()})


class Ran(subprocess.CompletedProcess):
    """A finished ``python -m mpdem``: ``returncode``, ``stdout``, ``stderr``, and ``out`` (both)."""

    @property
    def out(self):
        return self.stdout + self.stderr


def child_env(add=None, clean=False):
    """The environment of a child process.

    This process's environment as Python sees it (``os.environ``), not the C environment an
    in-process MPI singleton may have changed (its PMIx variables confuse a child mpiexec, which
    then exits 1 without a word); this tree's ``src`` first on PYTHONPATH; with ``clean``, without
    the ``MPDEM_*``, ``SLURM_*`` and ``PBS_*`` variables of a shell or job the tests run in (the job
    helper and the sweep read them); then ``add``.
    """
    env = {k: v for k, v in os.environ.items() if not (clean and k.startswith(CLUSTER_VARS))}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src")] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    env.update(add or {})
    return env


def fake_segment_mpdem(path, log):
    """A stand-in for the job helper's mpdem command (``MPDEM_CMD="bash PATH"``): appends its
    arguments to ``log``, one line per call, and finishes as ``mpdem run --out DIR`` does, with
    DIR/summary.json (the helper takes exit 0 without it for a launch that never started)."""
    path.write_text('printf "%s\\n" "$*" >> ' + shlex.quote(str(log)) + '\n'
                    'while (( $# )); do\n'
                    '  [[ $1 != --out ]] || { mkdir -p "$2"; echo "{}" > "$2/summary.json"; }; shift\n'
                    'done\n')
    return f"bash {path}"


def mpdem_argv(*args, n=1):
    """``python -m mpdem ARGS``, under ``mpiexec -n n`` (the venv's) when n > 1."""
    return ([str(MPIEXEC), "-n", str(n)] if n > 1 else []) + [sys.executable, "-m", "mpdem", *map(str, args)]


def mpdem(*args, n=1, cwd=None, env=None, clean=False, timeout=600, check=None):
    """``python -m mpdem ARGS`` in a real process (on ``n`` ranks), as users run it: a ``Ran``.

    ``env``: variables added to ``child_env(clean=clean)``. ``check``: the exit code expected
    (asserted, with the ends of the output). Every test that runs the command line goes through here.
    """
    p = subprocess.run(mpdem_argv(*args, n=n), cwd=cwd, capture_output=True, text=True,
                       env=child_env(env, clean), timeout=timeout)
    p = Ran(p.args, p.returncode, p.stdout, p.stderr)
    if check is not None:
        assert p.returncode == check, p.stdout[-3000:] + p.stderr[-3000:]
    return p
