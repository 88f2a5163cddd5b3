"""Flow arrest (docs/model.md 5.5): a run whose first ``flow.time`` tau flow down an incline of
``flow.incline`` degrees, after which gravity takes the config's own tilt (``box.incline``, the arrest
angle) and the stop rule starts its window.

One config makes the paper's second protocol: the spheres rain onto the tilted bed (or a settled pile
given as ``run.initial_file`` is tilted) and flow; at the step ``end`` = round(flow.time / dt) the
incline drops and the pile settles. Only the gravity vector changes (``law.gravity_vector``); the law
of a step is a function of the step alone, so a restart inside the flow goes on with the same laws on
every rank and engine, and the stop rule's window, cleared while the pile flows, starts at ``end``.
The flow itself is measured from snapshots (``analysis/flow.py``: v_x(z), phi(z), the temperature).
"""
from __future__ import annotations

from .kernels.law import gravity_vector


def end_step(flow_time, dt):
    """The first step after a flow of ``flow_time`` tau at time step ``dt`` (rounded to whole steps)."""
    return max(1, int(round(flow_time / dt)))


class FlowPhase:
    """The laws of a flow-arrest run, step by step (the interface of ``stiffen.Ramp``).

    Parameters
    ----------
    cfg : Config
        ``flow.*``, ``box.gravity`` and ``integration.dt``.
    law : kernels.law.Law
        The config's law (``Physics.law``, gravity tilted by ``box.incline``): the one from ``end`` on.

    Attributes
    ----------
    end : int
        The first step with the config's law; the stop rule counts from there.
    """

    def __init__(self, cfg, law):
        self.final = law
        self.incline, self.arrest = cfg.flow.incline, cfg.box.incline
        g_x, g_y, g_z = gravity_vector(cfg.box.gravity, cfg.flow.incline)
        self.flow = law._replace(g_x=g_x, g_y=g_y, g_z=g_z)
        self.end = end_step(cfg.flow.time, cfg.integration.dt)

    @classmethod
    def from_config(cls, cfg, law):
        """The flow phase of ``cfg``, or None without one (``flow.incline`` = 0)."""
        return cls(cfg, law) if cfg.flow.incline > 0 else None

    def active(self, step):
        """Whether the law of ``step`` is still the flow's (step < end)."""
        return step < self.end

    def law(self, step):
        """The ``Law`` of the force evaluation at ``step``."""
        return self.flow if step < self.end else self.final

    def room(self, step):
        """Steps after ``step`` that share the law of ``step + 1``; unbounded (a large number) past
        the flow."""
        first = step + 1
        return self.end - first if first < self.end else 1 << 62

    def describe(self, dt):
        """One log line."""
        return (f"flow arrest: gravity tilted by {self.incline:g} degrees for {self.end} steps "
                f"({self.end * dt:g} tau), then by {self.arrest:g} degrees; the stop rule from step {self.end}")
