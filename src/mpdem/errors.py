"""The base of every error mpdem reports to its user as one line (no traceback)."""


class MpdemError(Exception):
    """An input, file or run problem, said in one line naming what and why.

    Subclasses: ``config.ConfigError`` (and ``AgreedError``, ``sweep.SweepError``),
    ``build.InputError``, ``checkpoint.StateFileError``, ``schedule.RunError``,
    ``analysis.report.AnalysisError``, ``threads.ThreadsError``.
    """
