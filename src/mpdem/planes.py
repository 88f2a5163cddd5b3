"""Boundaries as planes: one record for the bed-making floor, the wall under the bed and any other
flat boundary (a lid, a side wall), and their arrays for the kernels.

A plane is the set of points p with n . p = offset; it holds spheres on the side its unit normal n
points to, at rest and of infinite mass. Its kind says which law it pushes with
(``kernels.law.plane_contact``): the bed-making floor's frictionless spring, the pile's normal law
(smooth), or the pile's whole law with a tangential history per sphere (rough: the wall under the
bed, whose history is the state's ``wall_ds``). Both engines add the planes after the
pair contacts, in the order of ``of_physics``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .kernels.law import PLANE_FLOOR, PLANE_ROUGH, PLANE_SMOOTH

KINDS = {"floor": PLANE_FLOOR, "smooth": PLANE_SMOOTH, "rough": PLANE_ROUGH}


@dataclass(frozen=True)
class Plane:
    """A flat boundary.

    Attributes
    ----------
    normal : (3,) tuple of float
        Unit normal n, pointing to the side the spheres are on.
    offset : float
        n . p of the plane's points [d].
    kind : {"floor", "smooth", "rough"}
        The law it pushes with (module docstring).
    """
    normal: tuple
    offset: float = 0.0
    kind: str = "smooth"

    def __post_init__(self):
        n = tuple(float(c) for c in self.normal)
        if len(n) != 3 or not math.isclose(math.fsum(c * c for c in n), 1.0, rel_tol=0.0, abs_tol=1e-12):
            raise ValueError(f"Plane normal {self.normal!r}: accepted a unit vector of 3 components")
        if self.kind not in KINDS:
            raise ValueError(f"Plane kind {self.kind!r}: accepted {', '.join(KINDS)}")
        object.__setattr__(self, "normal", n)

    @classmethod
    def lid(cls, height, kind="smooth"):
        """The plane z = ``height`` [d], facing down."""
        return cls((0.0, 0.0, -1.0), -float(height), kind)


# the bed-making floor and the wall under the bed (bed.wall): the plane z = 0, facing up
FLOOR = Plane((0.0, 0.0, 1.0), 0.0, "floor")
WALL = Plane((0.0, 0.0, 1.0), 0.0, "rough")


def of_physics(physics):
    """The planes of an ``engine.base.Physics``, in the order the engines add them: the floor (bed
    making), the wall (``bed.wall``), then ``physics.planes``."""
    extra = tuple(physics.planes)
    if any(p.kind == "rough" for p in extra):
        raise ValueError("a rough plane other than the wall under the bed (bed.wall): the state files keep "
                         "the tangential history of that one only (wall_ds); accepted kinds: floor, smooth")
    return ((FLOOR,) if physics.floor else ()) + ((WALL,) if physics.wall else ()) + extra


def of_config(cfg):
    """The planes a run of ``cfg`` has besides the bed-making floor: the wall under the bed
    (``bed.wall``), which a pile resting on a sparse bed leans on (the analyses' supports)."""
    return (WALL,) if cfg.bed.wall else ()


def arrays(planes):
    """The kernels' arrays of ``planes``: (P, 4) float64 normals and offsets, (P,) int64 kinds."""
    geo = np.array([p.normal + (p.offset,) for p in planes], dtype=np.float64).reshape(-1, 4)
    return geo, np.array([KINDS[p.kind] for p in planes], dtype=np.int64)
