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
