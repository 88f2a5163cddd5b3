"""The base of every error mpdem reports to its user as one line (no traceback), and the exit codes."""

# exit codes of the commands (README "Restart, wall time and exit codes")
EXIT_OK = 0              # finished: the pile came to rest
EXIT_ERROR = 1           # an error, said in one line
EXIT_USAGE = 2           # bad command line (argparse exits with it; named here for the table)
EXIT_NOT_CONVERGED = 3   # finished at run.max_steps without converging: a result
EXIT_RESTART = 75        # stopped on purpose (wall time or signal) after a checkpoint: restart me


class MpdemError(Exception):
    """An input, file or run problem, said in one line naming what and why.

    Subclasses: ``config.ConfigError`` (and ``AgreedError``, ``sweep.SweepError``),
    ``build.InputError``, ``checkpoint.StateFileError``, ``schedule.RunError``,
    ``analysis.report.AnalysisError``, ``threads.ThreadsError``.
    """
