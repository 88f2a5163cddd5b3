"""The paper campaign: many runs, and the paper's tables and figures from them.

``sweep`` (``mpdem sweep``: tables of runs), ``collect`` (``mpdem collect``),
``runs`` (runs, parameter sets, families), ``pooled`` (measures pooled over seeds
and fitted over sets), ``figures`` (Figs. 2-9), ``comparison`` (against the
paper) and ``paper`` (the paper's numbers). The measurements of one packing are
in ``mpdem.analysis``.
"""
