"""The analysis stage: measurements of docs/model.md section 6 on static packings.

One packing: ``bulk`` (bulk region, contacts, z, phi_f), ``contacts``,
``backbone`` (rattlers under gravity), ``nearcontact`` (alpha), ``bands``,
``order``, ``gofr`` (g(r) in the slab), ``mobilisation`` (P(zeta)), ``fits``
(eqs. 6, 7, 9), ``report`` (``mpdem analyze``: summary.json, CSV tables),
``series`` and ``plots``. Many runs (``mpdem collect``, the figures, the
comparison with the paper) are in ``mpdem.campaign``.
"""
from .bulk import (Packing, bulk_region, bulk_summary, coordination, find_contacts,
                   packing_fraction, phi_profile, remove_rattlers, slab_volume)

__all__ = ["Packing", "bulk_region", "bulk_summary", "coordination", "find_contacts",
           "packing_fraction", "phi_profile", "remove_rattlers", "slab_volume"]
