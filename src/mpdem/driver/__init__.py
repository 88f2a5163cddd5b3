"""The run: what drives the engine from a start to a finished run directory.

``simulation`` (``Run``: a new run or a run from a state file, and its time-step
loop), ``schedule`` (what happens between steps, each with its restart record),
``runstate`` (those records in a state file), ``resume`` (choosing a restart's
file), ``summary`` (the end of a run) and ``rundir`` (the run directory's files).
The package is not called ``run`` because ``mpdem.run`` is the API function.
"""
