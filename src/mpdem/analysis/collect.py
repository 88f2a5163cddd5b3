"""``mpdem collect``: many analysed runs -> the paper's tables and figures (placeholder, in progress)."""


def collect(runs, out, analyze_missing=True, log=print):
    raise NotImplementedError("mpdem collect is not built yet")
