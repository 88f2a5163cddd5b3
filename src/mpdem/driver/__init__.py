"""The run: what drives the engine from a start to a finished run directory.

``simulation`` (``Run``: a new run or a run from a state file, and its time-step
loop), ``schedule`` (what happens between steps, each with its restart record),
``runstate`` (those records in a state file), ``resume`` (choosing a restart's
file), and ``summary`` (the end of a run). The run directory's layout and its
atomic writes are ``mpdem.io.rundir``, which ``io`` and ``analysis`` use too.
The package is not called ``run`` because ``mpdem.run`` is the API function.
"""
