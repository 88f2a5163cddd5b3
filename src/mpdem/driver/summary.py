"""The end of a run: RUN/summary.json and the closing log lines.

``Run.finish`` writes RUN/final.h5 on every rank once the loop has ended
with "converged" or "max_steps" (an interrupted run ends with its checkpoint
instead), then rank 0 gives ``write`` an ``End``: what the run came to.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

from .. import analysis, planes
from ..io import checkpoint
from ..io import rundir


@dataclass
class End:
    """What a run came to, as ``Run.finish`` reports it to ``write``.

    Attributes
    ----------
    status : str
        "converged" or "max_steps".
    steps, segment_steps : int
        Steps of the whole run, and of this segment.
    time : float
        Simulated time [tau].
    n_mobile : int
    L_x, L_y : float
        The box [d].
    ek : float
        Kinetic energy per mobile sphere at the end [m g d].
    force_ratio : float
        The unbalanced-force ratio of the last sample.
    wall, wall_total : float
        Loop wall time of this segment, and of all segments [s].
    segments, ranks : int
    comm_seconds : float
        This segment's time in communication [s].
    parallel : bool
        More than one rank.
    migrated, rebalances : int
        Of the whole run (summed over ranks).
    """
    status: str
    steps: int
    segment_steps: int
    time: float
    n_mobile: int
    L_x: float
    L_y: float
    ek: float
    force_ratio: float
    wall: float
    wall_total: float
    segments: int
    ranks: int
    comm_seconds: float
    parallel: bool
    migrated: int
    rebalances: int

    @property
    def converged(self):
        return self.status == "converged"


def finish(run):
    """``run.finish()`` (the name of earlier versions)."""
    return run.finish()


def measure_bulk(state, domain, cfg):
    """The bulk measurement of the final state, each rank on its own rows and ghosts
    (``analysis.bulkpar.measure``; a collective): the bulk dict, or why there is none (str).

    The rows are brought current first (an engine that holds them elsewhere, the GPU's, copies them
    back), then the ghosts refreshed from them (the host's ghost rows need not be the engine's)."""
    from ..analysis import bulkpar
    from ..analysis.bulk import NoBulk
    if state.sync is not None:
        state.sync()
    domain.refresh(state)
    n = state.n_rows
    a = cfg.analysis
    try:
        return bulkpar.measure(state.x[:n], state.fixed[:n], state.id[:n], state.n_own, state.L_x, state.L_y,
                               cfg.contact.mu, domain, a.margin_bottom, a.margin_top, a.n_min, a.profile_bin,
                               a.tall_pile, rattlers=a.rattlers, k_n=cfg.contact.k_n, model=cfg.contact.model,
                               force_fraction=a.force_fraction, band_width=a.band_width,
                               planes=planes.of_config(cfg))
    except NoBulk as e:          # decided by reduced numbers: alike on every rank
        return str(e)


def write(end, digest, bulk, cfg, out, final, log):
    """Write summary.json and log the end and the bulk z and phi (rank 0).

    Parameters
    ----------
    end : End
    digest : str
        ``checkpoint.digest`` of the whole final state (``checkpoint.digest_parts``).
    bulk : dict, str or None
        The bulk measurement of the final state (``measure_bulk``), why it could not be made, or None
        where ``output.bulk_at_end`` is off (``mpdem analyze`` makes it later).
    cfg : Config
    out : str
        The run directory.
    final : str
        Path of the final state file written.
    log : schedule.Logger

    Returns
    -------
    dict
        The summary (also in RUN/summary.json).
    """
    steps = end.steps
    ns = 1e9 * end.wall / max(end.segment_steps * max(end.n_mobile, 1), 1)
    summary = {"steps": steps, "time": end.time, "converged": end.converged, "status": end.status,
               "E_k_per_particle": end.ek, "force_ratio": end.force_ratio, "wall_seconds": end.wall_total,
               "segments": end.segments,
               "ns_per_particle_step": ns, "ranks": end.ranks,
               "comm_share": end.comm_seconds / max(end.wall, 1e-9),
               "migrated": end.migrated, "rebalances": end.rebalances,
               "digest": digest}
    par = ""
    if end.parallel:
        par = (f"; {end.ranks} ranks, communication {100 * summary['comm_share']:.0f}%, "
               f"{end.migrated} migrations, {end.rebalances} rebalances")
    log(f"end: {'converged' if end.converged else 'NOT CONVERGED (hit run.max_steps)'} after "
        f"{steps} steps, t = {end.time:.4g}, E_k/N = {end.ek:.3e}, wall {end.wall:.1f} s "
        f"({ns:.0f} ns per particle-step{par})")
    if bulk is None:
        log(f"bulk: not measured at the end (output.bulk_at_end = false): `python -m mpdem analyze {out}` "
            f"measures it from the final state")
    elif isinstance(bulk, str):
        log.warn(f"no bulk measurement: {bulk}")
    else:
        summary["bulk"] = bulk
        log(f"bulk: z = {bulk['z']:.3f} (without rattlers by the {bulk['rattlers']} rule "
            f"{analysis.bulk.rattlers_text(bulk)}), phi = {bulk['phi']:.4f}, "
            f"{bulk['n_bulk']} particles in z in [{bulk['z1']:.2f}, {bulk['z2']:.2f}], "
            f"surface h = {bulk['h']:.2f}")
    rundir.write_json(os.path.join(out, "summary.json"), summary)
    log(f"wrote {final}")
    if not end.converged:
        # the exit code that follows is a result, not a crash (mpiexec reports it at length)
        log(f"exit status 3: the run reached run.max_steps = {cfg.run.max_steps} before the stop rule held; "
            f"not an error, and not used for comparisons. Go on with `python -m mpdem restart {out} "
            f"--set run.max_steps=...`")
    return summary


def recover(out, final, status):
    """Write ``out``/summary.json for a run that ended (``final``: its final state file) but whose
    summary was never written (the process ended between the two files): what the state file says,
    marked ``recovered``. E_k_per_particle is the stop rule's last sample (what ``write`` reports);
    the last segment's timing, communication share and force ratio are not known (None). The digest is
    the final state's, as ``write`` takes it. Returns the summary (rank 0, one process).
    """
    arrays, attrs = checkpoint.read_state(final)
    rs = json.loads(attrs.get("run_state") or "{}")
    history = rs.get("history", {})
    samples = rs.get("stop", {}).get("stop_samples") or []
    summary = {"steps": int(attrs["step"]), "time": float(attrs["time"]), "converged": status == "converged",
               "status": status, "E_k_per_particle": samples[-1] if samples else None, "force_ratio": None,
               "wall_seconds": history.get("wall_seconds"), "segments": history.get("segments"),
               "ns_per_particle_step": None, "ranks": int(attrs["ranks"]), "comm_share": None,
               "migrated": history.get("migrated"), "rebalances": history.get("rebalances"),
               "digest": checkpoint.digest(arrays),
               "recovered": f"written by a restart from {os.path.basename(final)}: the run ended before its summary "
                            f"was written"}
    rundir.write_json(os.path.join(out, "summary.json"), summary)
    return summary
