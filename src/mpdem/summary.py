"""The end of a run: RUN/final.h5, RUN/summary.json, and the closing log lines.

``finish`` is called on every rank once the loop has ended with "converged"
or "max_steps" (an interrupted run ends with its checkpoint instead).
"""
from __future__ import annotations

import os

from . import analysis, checkpoint, rundir


def finish(run):
    """Write the final state (with the contact list) and summary.json; log bulk z and phi.

    Parameters
    ----------
    run : simulation.Run
        After ``run.run()``.

    Returns
    -------
    dict or None
        The summary on rank 0 (also in RUN/summary.json), None elsewhere.
    """
    cfg, st, log, dom = run.cfg, run.state, run.log, run.domain
    # collectives first, in the same order on every rank
    arrays = dom.gather_arrays(checkpoint.gather_state(st))
    migrated, rebalances = run.counters()
    path = run.snapshots.write(final=True)
    if run.rank != 0:
        log.close()
        return None
    steps = st.step
    ns = 1e9 * run.wall / max((steps - run.first_step) * max(run.n_mobile, 1), 1)
    summary = {"steps": steps, "time": st.time, "converged": run.converged, "status": run.status,
               "E_k_per_particle": run.ek, "force_ratio": run.force_ratio, "wall_seconds": run.wall_total(),
               "segments": run.history.segments,
               "ns_per_particle_step": ns, "ranks": dom.size,
               "comm_share": dom.comm_seconds / max(run.wall, 1e-9),
               "migrated": migrated, "rebalances": rebalances,
               "digest": checkpoint.digest(arrays)}
    par = ""
    if dom.parallel:
        par = (f"; {dom.size} ranks, communication {100 * summary['comm_share']:.0f}%, "
               f"{migrated} migrations, {rebalances} rebalances")
    log(f"end: {'converged' if run.converged else 'NOT CONVERGED (hit run.max_steps)'} after "
        f"{steps} steps, t = {st.time:.4g}, E_k/N = {run.ek:.3e}, wall {run.wall:.1f} s "
        f"({ns:.0f} ns per particle-step{par})")
    try:
        a = cfg.analysis
        bulk = analysis.bulk_summary(arrays["x"], arrays["fixed"], st.L_x, st.L_y, cfg.contact.mu,
                                     a.margin_bottom, a.margin_top, a.n_min, a.profile_bin, a.tall_pile,
                                     rattlers=a.rattlers, k_n=cfg.contact.k_n, model=cfg.contact.model,
                                     force_fraction=a.force_fraction, band_width=a.band_width)
        summary["bulk"] = bulk
        log(f"bulk: z = {bulk['z']:.3f} (without rattlers {bulk['z_no_rattlers']:.3f} by the {bulk['rattlers']} rule, "
            f"rattlers {100 * bulk['rattler_fraction']:.1f}%), phi = {bulk['phi']:.4f}, "
            f"{bulk['n_bulk']} particles in z in [{bulk['z1']:.2f}, {bulk['z2']:.2f}], "
            f"surface h = {bulk['h']:.2f}")
    except ValueError as e:
        log.warn(f"no bulk measurement: {e}")
    rundir.write_json(os.path.join(run.out, "summary.json"), summary)
    log(f"wrote {path}")
    if not run.converged:
        # the exit code that follows is a result, not a crash (mpiexec reports it at length)
        log(f"exit status 3: the run reached run.max_steps = {cfg.run.max_steps} before the stop rule held; "
            f"not an error, and not used for comparisons. Go on with `python -m mpdem restart {run.out} "
            f"--set run.max_steps=...`")
    log.close()
    return summary
