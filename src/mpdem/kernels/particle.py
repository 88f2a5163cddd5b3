"""The particle of the model, in one place (docs/model.md section 1).

All spheres are equal: diameter d = 1, mass m = 1, so R = 1/2 and the moment
of inertia of a solid sphere is I = (2/5) m R^2 = 0.1. The kernels read these
as compile-time constants; the Python modules that need them import them
from here.
"""
import math

R = 0.5                  # radius [d]
VOLUME = math.pi / 6.0   # (4/3) pi R^3 [d^3]
INERTIA = 0.1            # moment of inertia I = (2/5) m R^2 [m d^2]
INV_I = 10.0             # 1 / I [1 / (m d^2)], exactly 1.0 / INERTIA in floating point
HALF_I = 0.05            # I / 2 of the rotational kinetic energy (1/2) I omega^2 [m d^2], exactly 0.5 * INERTIA
