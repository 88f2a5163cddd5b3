"""Restart: choose the state file and check it and its config.

``open_target`` picks the newest usable state file of a run directory (or
takes the file given), reads this rank's share of it collectively, reads its
restart records (``runstate.RunState``) and resolves the restart's config.
``verdict`` says whether there is anything to do; ``simulation.Run.from_file``
then builds the run's next segment from the ``Target``. The next step is bit
for bit the one the straight run takes (ARCHITECTURE.md, invariants).
"""
from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass

from ..io import checkpoint, diskspace
from .. import config
from ..flowarrest import end_step
from ..io import rundir
from ..io.checkpoint import StateFileError
from ..errors import EXIT_NOT_CONVERGED, EXIT_OK, WriteError
from .runstate import RunState

# attributes a state file needs to be restarted from
NEEDED = ("run_state", "n_mobile", "n_bed", "config")


@dataclass
class Target:
    """A state file chosen for a restart, read, with its config resolved.

    Attributes
    ----------
    path : str
    run_dir : str
    local : dict of arrays
        This rank's share of the file (``checkpoint.read``).
    attrs : dict
    cfg : Config
        The restart's config: the file's, with --set.
    stop_changed : list of str
        ``stop.*`` keys that --set changed.
    skipped : list of str
        Why newer files were passed over.
    records : runstate.RunState
        The restart records of the run and its schedules (the ``run_state`` attribute).
    """
    path: str
    run_dir: str
    local: dict
    attrs: dict
    cfg: object
    stop_changed: list
    skipped: list
    records: RunState


def candidates(target):
    """Files a restart of ``target`` may start from, newest first, the run directory, and the files
    passed over, each with why.

    A directory gives its checkpoints and final.h5, ordered by step (from the file attributes); a
    file whose attributes cannot be read (truncated, not HDF5, another format) is passed over and
    named. A file gives itself; its run directory is the parent of ``checkpoints/`` or the directory
    it is in.

    Returns
    -------
    files : list of str
    run_dir : str
    passed : list of str
        ``"<file>: <what is wrong>"`` of each file passed over.
    """
    if not os.path.isdir(target):
        return [target], run_dir_of(target), []
    run = target
    files = [p for _, p in rundir.checkpoints(run)]
    if os.path.exists(rundir.final_path(run)):
        files.append(rundir.final_path(run))
    if not files:
        raise StateFileError(f"{run}: no checkpoints/ckpt-*.h5 and no final.h5 to restart from")
    steps, passed = {}, []
    for p in files:
        try:
            steps[p] = int(checkpoint.read_attrs(p)["step"])
        except StateFileError as e:
            passed.append(str(e))
        except KeyError:
            passed.append(f"{p}: no step attribute; not a state file of a run")
    # newest first; at equal steps the final state (it knows the run ended)
    order = sorted(steps, key=lambda p: (steps[p], p == rundir.final_path(run)), reverse=True)
    return order, run, passed


def run_dir_of(target):
    """The run directory of a restart target: the directory itself, or the run a state file is of
    (the parent of ``checkpoints/`` or ``snapshots/``, else the directory it is in).

    Raises
    ------
    StateFileError when ``target`` does not exist.
    """
    if os.path.isdir(target):
        return target
    if not os.path.exists(target):
        raise StateFileError(f"{target}: no such file or directory")
    d = os.path.dirname(os.path.abspath(target))
    return os.path.dirname(d) if os.path.basename(d) in (rundir.CKPT_DIR, rundir.SNAP_DIR) else d


def restart_config(attrs, path, run, sets):
    """The config of a restart: the file's, checked against RUN/config.toml, with --set.

    Raises StateFileError when the run directory's config differs from the
    checkpoint's in a key that changes the arithmetic, and ConfigError when
    --set tries to change such a key.
    """
    try:
        # the keys derived in the run stay derived: a restart leaves config.toml as it was
        raw = config.raw_from_toml(attrs.get("config", ""), origin=path)
        cfg = config.resolve(raw)
    except (tomllib.TOMLDecodeError, config.ConfigError) as e:
        raise StateFileError(f"{path}: its config is unusable ({e})") from None
    ours = os.path.join(run, "config.toml")
    if os.path.exists(ours):
        try:
            mine = config.load(ours)
        except config.ConfigError as e:
            raise StateFileError(f"{ours}: {e}") from None
        diff = _fixed_keys_differing(cfg, mine)
        if diff:
            k = diff[0]
            raise StateFileError(f"{path} does not match {ours}: {k} = {cfg.values[k]!r} in the checkpoint, "
                                 f"{mine.values[k]!r} in the run directory ({len(diff)} keys differ); "
                                 f"restart from a checkpoint of this run")
    if sets:
        new = config.load(None, sets, base=raw)
        bad = _fixed_keys_differing(new, cfg)
        if "flow.time" in bad:
            _check_flow_time(cfg, new, int(attrs.get("step", 0)), path)
            bad.remove("flow.time")
        if bad:
            raise config.ConfigError(
                f"--set {bad[0]}={new.values[bad[0]]!r}: a restart can change only "
                f"{config.key_summary(config.RESTART_KEYS)} (and flow.time while the flow runs); "
                f"to continue with other physics start a new run with --set run.initial_file={path}")
        cfg = new
    return cfg


def _check_flow_time(old, new, step, path):
    """Allow ``--set flow.time`` at a restart only inside the flow (docs/model.md 5.5): a flow found not
    yet steady may run longer, or shorter, while it runs; the steps before are the same either way, so
    the run is the straight run of the new flow.time. Raises ConfigError otherwise (a flow.time without a
    flow phase the config refuses itself)."""
    dt = old.integration.dt
    end_old, end_new = end_step(old.flow.time, dt), end_step(new.flow.time, dt)
    want = f"--set flow.time={new.flow.time:g}"
    if step >= end_old:
        raise config.ConfigError(f"{want}: {path} is at step {step}, past its flow's end at step {end_old} "
                                 f"(flow.time = {old.flow.time:g}): flow.time can change only while the flow runs")
    if step >= end_new:
        raise config.ConfigError(f"{want}: the flow would end at step {end_new}, before {path}'s step {step}; "
                                 f"accepted: a flow.time above {step * dt:g} tau")


def _fixed_keys_differing(a, b):
    """Keys a restart may not change (not in config.RESTART_KEYS) whose values differ between two Configs."""
    return [k for k in config.KEYS if not config.KEYS[k].restart and a.values[k] != b.values[k]]


def open_target(target, net, sets):
    """The newest usable state file of ``target`` (a run directory or a state file), read collectively.

    Parameters
    ----------
    target : str
    net : parallel.Channel
    sets : list of str
        ``--set key=value`` (only keys that may change at restart).

    Returns
    -------
    Target

    Raises
    ------
    StateFileError
        On every rank alike: no usable file (each one's reason listed).
    """
    # rank 0 chooses the order; every rank then reads the same files collectively
    files, run_dir, skipped = net.on_root(candidates, target, catch=StateFileError)
    for path in files:
        try:
            local, attrs = checkpoint.read(path, net)
            missing = [k for k in NEEDED if k not in attrs]
            if attrs.get("kind") not in checkpoint.KINDS or missing:
                raise StateFileError(f"{path}: a {attrs.get('kind')!r} file without {', '.join(missing) or 'a run'}; "
                                     f"restart accepts the checkpoints, snapshots and final.h5 of a run")
            try:
                records = RunState.loads(attrs["run_state"])
            except (ValueError, TypeError) as e:
                raise StateFileError(f"{path}: its run_state is unusable ({e})") from None
            cfg = restart_config(attrs, path, run_dir, sets)
            # the file's own config, to see which stop.* keys --set changed
            old = config.resolve(config.raw_from_toml(attrs["config"], origin=path))
            changed = [k for k in cfg.values if k.startswith("stop.") and cfg.values[k] != old.values[k]]
            return Target(path, run_dir, local, attrs, cfg, changed, skipped, records)
        except StateFileError as e:
            if not os.path.isdir(target):
                raise
            skipped.append(str(e))
    raise StateFileError(f"{run_dir}: no usable state file to restart from:\n  " + "\n  ".join(skipped))


def check_room(t, net):
    """Raise WriteError on every rank when ``t``'s run directory has no room for a state file as large as
    ``t``'s (the restart writes checkpoints and a final state): said before the restart starts."""
    def look():
        # the size of the file it starts from, and some room for the log and thermo lines
        return diskspace.room_in(t.run_dir, os.path.getsize(t.path) + 65536, f"the state files of {t.run_dir}")
    why = net.on_root(look)
    if why:
        raise WriteError(f"restart: {why}; make room, then restart again (nothing was changed)", agreed=True)


def verdict(t, say):
    """Whether to go on from ``t``: None to resume, else the exit status (nothing to do).

    A converged run goes on only under a stop rule changed by --set; a final
    state at ``run.max_steps`` needs a higher cap. ``say`` (a Logger) takes
    the lines that explain it, and warnings for skipped files.
    """
    path, attrs, cfg = t.path, t.attrs, t.cfg
    for e in t.skipped:
        say.warn(f"restart: skipping {e}")
    if t.skipped:
        say.warn(f"restart: falling back to {path} (step {attrs['step']})")
    if attrs.get("converged") and not t.stop_changed:
        say(f"restart: {path}: the run converged at step {attrs['step']}; nothing to do")
        return EXIT_OK
    if attrs.get("converged"):
        say(f"restart: {path} converged at step {attrs['step']}; going on under the changed stop rule "
            f"({', '.join(f'{k} = {cfg.values[k]!r}' for k in t.stop_changed)})")
    # a checkpoint at the cap still goes on, to write the final state
    if attrs.get("kind") == "final" and int(attrs["step"]) >= cfg.run.max_steps:
        say(f"restart: {path} is at step {attrs['step']} and run.max_steps = {cfg.run.max_steps}; "
            f"raise it with --set run.max_steps=... to go on")
        return EXIT_NOT_CONVERGED
    return None
