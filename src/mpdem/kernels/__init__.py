"""numba kernels: arrays and scalars in, preallocated arrays out.

Kernels never touch configs, MPI, logging or Python objects (ARCHITECTURE.md,
invariant 4). Buffers have a capacity; a kernel that would overflow one
reports the size it needs and the caller grows the buffer and calls again.
No ``fastmath`` anywhere: results must be bit-identical for any rank count.
"""
