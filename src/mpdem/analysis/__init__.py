"""The analysis stage: measurements of physics.md section 6 on static packings.

``bulk`` (bulk region, contacts, z, phi_f), ``gofr`` (g(r) in the slab),
``forces`` (P(zeta)), ``fits`` (eqs. 6, 7, 9), ``report`` (``mpdem analyze``
of one file: summary.json, CSV tables, plots), ``collect`` (many runs: the
paper's tables and figures).
"""
from .bulk import (Packing, bulk_region, bulk_summary, coordination, find_contacts,
                   packing_fraction, phi_profile, remove_rattlers, slab_volume)

__all__ = ["Packing", "bulk_region", "bulk_summary", "coordination", "find_contacts",
           "packing_fraction", "phi_profile", "remove_rattlers", "slab_volume"]
