"""Which spheres hold a pile's rotational energy: the stop rule's spin hint names them (docs/model.md 5.4)."""
import numpy as np

from ..kernels.particle import HALF_I


def spinners(state, domain, top=3):
    """The ``top`` mobile spheres of the largest rotational energy, over all ranks (a collective).

    Parameters
    ----------
    state : State
        Brought current first (``state.sync``, the engine's).
    domain : Domain
    top : int

    Returns
    -------
    spheres : list of (energy [m g d], id, contacts, |omega| [sqrt(g/d)])
        Largest first; contacts are those in touch at the last force evaluation, the bed's included.
    total : float
        The rotational energy of every mobile sphere [m g d].
    """
    if state.sync is not None:
        state.sync()
    n = state.n_own
    w = state.omega[:n]
    e = np.where(state.fixed[:n] == 0, HALF_I * np.einsum("ij,ij->i", w, w), 0.0)
    k = min(top, n)
    rows = np.argpartition(-e, k - 1)[:k] if k else np.zeros(0, np.int64)
    mine = [(float(e[i]), int(state.id[i]), int(state.count[i]), float(np.sqrt(w[i] @ w[i]))) for i in rows]
    parts = domain.allgather((mine, float(e.sum())))
    spheres = sorted((s for part, _ in parts for s in part), key=lambda s: (-s[0], s[1]))[:top]
    return spheres, sum(t for _, t in parts)


def describe(spheres, total):
    """One sentence naming the spheres of ``spinners``: the largest's share of the rotational energy and
    all of theirs together."""
    if not spheres or not total > 0.0:
        return "no mobile sphere is spinning"
    e, ident, contacts, w = spheres[0]
    share = 100.0 * sum(s[0] for s in spheres) / total
    ids = ", ".join(str(s[1]) for s in spheres)
    return (f"{100.0 * e / total:.3g} % of the rotational energy is in sphere {ident} ({contacts} "
            f"contact{'' if contacts == 1 else 's'}, "
            f"|omega| = {w:.3g} sqrt(g/d)), {share:.4g} % in the {len(spheres)} largest (ids {ids})")
