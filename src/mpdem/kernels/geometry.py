"""Small geometric helpers inlined into the kernels."""
from numba import njit


@njit(cache=True, inline="always")
def min_image(d, length, half):
    """Minimum image of a raw coordinate difference |d| < length along a periodic axis.

    Mirror-exact: min_image(-d) == -min_image(d) bit for bit, so the two
    partners of a pair see exactly opposite separations.
    """
    if d > half:
        return d - length
    if d < -half:
        return d + length
    return d
