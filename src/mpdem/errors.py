"""The base of every error mpdem reports to its user as one line (no traceback), and the exit codes."""

# exit codes of the commands (README "Restart, wall time and exit codes")
EXIT_OK = 0              # finished: the pile came to rest
EXIT_ERROR = 1           # an error, said in one line
EXIT_USAGE = 2           # bad command line (argparse exits with it; named here for the table)
EXIT_NOT_CONVERGED = 3   # finished at run.max_steps without converging: a result
EXIT_RESTART = 75        # stopped on purpose (wall time or signal) after a checkpoint: restart me


class MpdemError(Exception):
    """An input, file or run problem, said in one line naming what and why.

    Every error mpdem raises is one of the kinds below, imported from here.

    Attributes
    ----------
    agreed : bool
        Every rank raises it together, with the same message: the command line says it once (rank 0)
        and every rank exits without MPI_Abort, whose teardown can lose the message. Otherwise one
        rank may be alone with it, and the command line ends every rank with MPI_Abort.
    """
    agreed = False


class ConfigError(MpdemError, ValueError):
    """A configuration value that cannot be run."""


class AgreedError(ConfigError):
    """A ConfigError that every rank raises together, from a value all ranks were given:
    the ranks stop without MPI_Abort, whose teardown can lose the message."""
    agreed = True


class SweepError(ConfigError):
    """A sweep table or sweep option that cannot be used (reported before any row runs)."""


class InputError(MpdemError, ValueError):
    """An initial configuration that cannot be run (``agreed``: raised by every rank together)."""

    def __init__(self, message, agreed=False):
        super().__init__(message)
        self.agreed = agreed


class StateFileError(MpdemError, ValueError):
    """A state file that cannot be used (named, with the reason)."""


class WriteError(MpdemError, RuntimeError):
    """A file that could not be written (named, with the reason: a full disk, a quota, no permission).

    Nothing is left under the file's real name: a state file's partial ``.tmp`` is removed. The
    collective state-file write raises it on every rank together (``agreed=True``), whatever rank
    failed; a writer on one rank (an export) raises it there alone.
    """

    def __init__(self, message, agreed=False):
        super().__init__(message)
        self.agreed = agreed


class PackingFileError(MpdemError, ValueError):
    """A packing file that cannot be read."""


class RunError(MpdemError, RuntimeError):
    """The run cannot go on (NaN, excessive overlap, a particle under the bed)."""


class AnalysisError(MpdemError, ValueError):
    """A file or a setting the analysis cannot use."""


class ThreadsError(MpdemError, ValueError):
    """A thread count that cannot be used."""


class DeviceError(MpdemError, RuntimeError):
    """The engine's device cannot be used: no GPU, no CUDA runtime, or numba-cuda missing."""


class Interrupted(MpdemError):
    """A stop signal (SIGTERM, SIGINT) before there was anything to save: the set-up ended early.

    Attributes
    ----------
    status : int
        The exit status: 128 + the signal's number (143 for SIGTERM, 130 for SIGINT).
    """

    def __init__(self, message, status=EXIT_ERROR):
        super().__init__(message)
        self.status = int(status)

    def __reduce__(self):
        # sent between ranks (``Channel.on_root``) with its status
        return (type(self), (str(self), self.status), {"agreed": self.agreed})


class MemoryRefused(MpdemError):
    """A run whose estimated memory a rank exceeds what the node has (said before any work)."""
