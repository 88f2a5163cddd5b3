"""The engines that step a rank's particles, behind one interface (design.md, "Two engines, one result").

Every engine is built as ``Engine(state, physics, domain)`` and offers:

- ``start()`` / ``start_from_file(max_overlap, n_rebuilds)``: lists and the set-up evaluation
  (from a state file: its forces kept), returning the first ``StepInfo``;
- ``step(flags, defer_kick, keep_pairs)`` -> ``StepInfo``, one velocity-Verlet step, reduced over the
  ranks in one allreduce. ``flags``: the driver's per-rank record of floats (``simulation.StepFlags``:
  signal, wall time, clock checkpoint), agreed by max in that allreduce and returned as
  ``info.flags``, of the same type. ``info.max_overlap`` is the previous force evaluation's (it
  travels in the same allreduce); ``info.n_contacts`` the last ``contacts()`` count. With
  ``defer_kick`` the step's second half-kick is left for the next step (the same bits); until then
  ``v`` and ``omega`` are the half-step values, and ``complete()`` applies it (every reader of the
  rows, through ``State.sync``, and ``kinetic`` call it first). ``keep_pairs`` keeps every pair's
  force of the step's evaluation for ``force_ratio`` (the same bits either way);
- ``run_quiet(n, flags)`` -> n StepInfos: n steps as ``step(flags, defer_kick=True)`` that nothing
  reads between (the driver's steps between samples, files and progress lines), which an engine may
  run without returning to Python (``steps_in_one_call``: the CPU's on one rank and one thread, the
  GPU's on one rank);
- ``advance(n)`` (``run_quiet``'s steps, then ``complete()``), ``complete()``;
- ``rebuild()``; ``kinetic()`` -> exact (translational, rotational) sums; ``contacts()``;
  ``force_ratio()``; ``sync_state()`` (the state's rows and compact contact slots current for a reader,
  attached as ``State.sync``); ``memory_bytes()``;
- ``info``, ``last_overlap``, ``n_rebuilds``, ``timers`` ("forces", "lists", "integration").

Two implementations: ``cpu.Engine`` (numba njit kernels and threads) and ``gpu.Engine`` (numba-cuda
kernels on one GPU per rank). Both give the same bits (docs/computing.md, "One law, two targets"),
so the driver, its schedules, the state files and the analysis do not know which one runs, and a
run may change device at a restart (``engine.device``).
"""
from __future__ import annotations

DEVICES = ("cpu", "gpu")


def engine_class(device):
    """The engine class of ``device`` ("cpu" or "gpu"); the GPU's imports numba-cuda, which
    raises ``errors.DeviceError`` naming what is missing when no GPU or CUDA runtime is found."""
    if device == "cpu":
        from .cpu import Engine
        return Engine
    if device == "gpu":
        from .gpu import Engine
        return Engine
    raise ValueError(f"engine.device = {device!r}: expected one of {', '.join(DEVICES)}")


def require(device):
    """Raise ``errors.DeviceError`` (one line) unless an engine of ``device`` can run here: called
    before a run does any work."""
    if device == "gpu":
        from .gpu import require as gpu_require
        gpu_require()


def make_engine(state, physics, domain, device="cpu", gpu_block=256, gpu_threads="row", gpu_max_registers=0,
                gpu_reductions="fused", gpu_samples="device", gpu_drift="fused", gpu_pinned=True,
                gpu_rebuild="launch", gpu_sort="host", gpu_exchange="host"):
    """An engine of ``device`` for ``state`` under ``physics`` over ``domain``; the ``gpu_*`` keywords: the
    GPU engine's threads per block, its threads of the forces, its kernels' register cap, its fused
    steps' reductions, where the stop rule's samples are summed, where its launches of many steps drift,
    whether those are compiled for the run's options, how its list rebuilds are sized, where it orders
    the rows and where a rebuild on several ranks keeps the history (``engine.gpu_*``, ``gpu_options``; no
    effect on results)."""
    if device == "gpu":
        return engine_class(device)(state, physics, domain, block=gpu_block, threads=gpu_threads,
                                    max_registers=gpu_max_registers, reductions=gpu_reductions, samples=gpu_samples,
                                    drift=gpu_drift, pinned=gpu_pinned, rebuilds=gpu_rebuild, sort=gpu_sort,
                                    exchange=gpu_exchange)
    return engine_class(device)(state, physics, domain)


def gpu_options(engine):
    """``make_engine``'s ``gpu_*`` keywords from a config's ``engine`` section (``cfg.engine``)."""
    return {"gpu_block": engine.gpu_block, "gpu_threads": engine.gpu_threads,
            "gpu_max_registers": engine.gpu_max_registers, "gpu_reductions": engine.gpu_reductions,
            "gpu_samples": engine.gpu_samples, "gpu_drift": engine.gpu_drift, "gpu_pinned": engine.gpu_pinned,
            "gpu_rebuild": engine.gpu_rebuild, "gpu_sort": engine.gpu_sort,
            "gpu_exchange": engine.gpu_exchange}
