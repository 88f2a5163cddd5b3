"""The GPU engine's kernels (numba-cuda): the law's explicitly rounded twins (``rounded``), the
runtime and its checks (``runtime``), and the step's kernels (``step``). Imported only by the GPU
engine, so that numba-cuda is needed only where a GPU runs (docs/gpu.md)."""
