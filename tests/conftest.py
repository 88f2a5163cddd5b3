import os

# the GPU engine's tests run under numba's CUDA simulator unless MPDEM_REAL_GPU=1 (tools/gpu_check.sh);
# set before anything imports numba, and inherited by the runs the tests start
if os.environ.get("MPDEM_REAL_GPU") != "1":
    os.environ["NUMBA_ENABLE_CUDASIM"] = "1"

import pytest  # noqa: E402

from helpers import make_engine  # noqa: E402
from mpdem import memory, threads  # noqa: E402
from mpdem.kernels.calls import Bound  # noqa: E402

# every 16th kernel call through an overload numba chose compares its argument types with the chosen ones
Bound.check = 16

# the process's threads and allocator as a run sets them (``simulation``; the engines set neither): one
# thread, not numba's default of every core, whose idle threads would wait on a core the others use
threads.apply()
memory.return_freed_memory()


@pytest.fixture
def engine_factory():
    return make_engine


def pytest_collection_modifyitems(config, items):
    """The files with long runs (a test marked ``validation``) first, each file's tests together and in
    their order (a module's fixtures are made once): pytest-xdist's workers start on the long runs, and
    the short tests fill the ends (``make test-pytest``)."""
    long = {item.path for item in items if item.get_closest_marker("validation")}
    items.sort(key=lambda item: item.path not in long)
