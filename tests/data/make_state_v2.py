"""Writes tests/data/state_v2.h5 (format mpdem-state v2) with checkpoint.write: 12 random particles."""
import sys
import numpy as np
from mpdem.io import checkpoint

rng = np.random.default_rng(24)
n = 12
ids = rng.permutation(n).astype(np.int64) + 5
count = rng.integers(0, 3, n)
m = int(count.sum())
local = dict(id=ids, x=rng.random((n, 3)) * 4, v=rng.normal(size=(n, 3)), omega=rng.normal(size=(n, 3)),
             f=rng.normal(size=(n, 3)), torque=rng.normal(size=(n, 3)), fixed=(ids < 8).astype(np.uint8),
             count=count, partner=rng.choice(ids, m), ds=rng.normal(size=(m, 3)) * 1e-3,
             wall_ds=rng.normal(size=(n, 3)) * 1e-3)
p = 5
local.update(id_i=rng.choice(ids, p), id_j=rng.choice(ids, p), delta=rng.random(p) * 1e-3, F_n=rng.random(p),
             F_t=rng.normal(size=(p, 3)), ds_i=rng.normal(size=(p, 3)) * 1e-3)
attrs = dict(kind="snapshot", step=7, time=0.0007, n=n, n_mobile=int((ids >= 8).sum()), n_bed=int((ids < 8).sum()),
             L_x=4.0, L_y=4.0, config="")
checkpoint.write(sys.argv[1], local, attrs)
a, _ = checkpoint.read_state(sys.argv[1], pairs=True)
print(checkpoint.digest(a))
