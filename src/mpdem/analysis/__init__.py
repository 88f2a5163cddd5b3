"""The analysis stage: measurements of docs/model.md section 6 on static packings.

One file: ``bulk`` (bulk region, contacts, z, phi_f), ``gofr`` (g(r) in the
slab), ``mobilisation`` (P(zeta)), ``fits`` (eqs. 6, 7, 9), ``report`` (``mpdem
analyze``: summary.json, CSV tables) and ``plots``.
Many runs (``mpdem collect``): ``runs`` (runs and parameter sets), ``collect``
(grouping, fits, tables), ``figures`` (Figs. 2-9), ``comparison`` (against
the paper's values in ``paper``).
"""
from .bulk import (Packing, bulk_region, bulk_summary, coordination, find_contacts,
                   packing_fraction, phi_profile, remove_rattlers, slab_volume)

__all__ = ["Packing", "bulk_region", "bulk_summary", "coordination", "find_contacts",
           "packing_fraction", "phi_profile", "remove_rattlers", "slab_volume"]
