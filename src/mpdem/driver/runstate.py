"""The ``run_state`` attribute of a state file: every restart record of a run, each under its own name.

A state file continues a run exactly when, besides its particles, it carries
the records of the run and of each schedule that keeps a count or a window
(ARCHITECTURE.md, data flow (c)). ``RunState`` holds them, typed; its JSON
keeps each record in its own object::

    {"history": {...}, "pile": {...}, "stop": {...}, "checkpoints": {...}, "snapshots": {...}}

so two records may use the same field name without crossing wires. Files
written before the namespaces (one flat object with the fields of every
record) still load (``RunState.loads``).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from ..initial import Pile
from .schedule import CheckpointRecord, SnapshotRecord, StopRecord, from_dict


@dataclass
class History:
    """Restart record of the run as a whole: its segments and counters so far."""
    segments: int = 1
    wall_seconds: float = 0.0       # loop wall time of all segments [s]
    n_rebuilds: int = 0
    max_overlap: float = 0.0        # of the last force evaluation [d]
    migrated: int = 0               # particles moved between ranks (summed over ranks)
    rebalances: int = 0


# the name of each record in run_state, and its type
RECORDS = {"history": History, "pile": Pile, "stop": StopRecord, "checkpoints": CheckpointRecord,
           "snapshots": SnapshotRecord}


@dataclass
class RunState:
    """The restart records of a run and its schedules (a new run's are the defaults).

    Attributes
    ----------
    history : History
        Segments and counters of the run (``simulation.Run``).
    pile : initial.Pile
        The pile's geometry, fixed at the start.
    stop : schedule.StopRecord
        The stop rule's window of samples.
    checkpoints, snapshots : schedule.CheckpointRecord, schedule.SnapshotRecord
        Files written so far (number the next).
    """
    history: History = field(default_factory=History)
    pile: Pile = field(default_factory=Pile)
    stop: StopRecord = field(default_factory=StopRecord)
    checkpoints: CheckpointRecord = field(default_factory=CheckpointRecord)
    snapshots: SnapshotRecord = field(default_factory=SnapshotRecord)

    def dumps(self):
        """The JSON text of the ``run_state`` attribute: one object per record."""
        return json.dumps({name: asdict(getattr(self, name)) for name in RECORDS})

    @classmethod
    def loads(cls, text):
        """The records of a ``run_state`` text, namespaced or (files written before the namespaces) flat.

        Fields a record does not know are ignored; missing ones take their defaults.

        Raises
        ------
        ValueError (json.JSONDecodeError) or TypeError when the text is not such a record.
        """
        d = json.loads(text)
        if not isinstance(d, dict):
            raise TypeError(f"a JSON object expected, not {type(d).__name__}")
        if any(isinstance(d.get(name), dict) for name in RECORDS):
            parts = {name: d.get(name, {}) for name in RECORDS}
        else:
            # the flat layout: every record took its fields from the one object
            parts = dict.fromkeys(RECORDS, d)
        bad = [name for name, part in parts.items() if not isinstance(part, dict)]
        if bad:
            raise TypeError(f"run_state.{bad[0]} is not a JSON object")
        return cls(**{name: from_dict(kind, parts[name]) for name, kind in RECORDS.items()})
