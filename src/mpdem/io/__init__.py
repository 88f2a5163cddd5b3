"""Files in and out: state files, packing files, text tables, LAMMPS files, exports.

``checkpoint`` (HDF5 state files: checkpoints, snapshots, ``final.h5``; the only
module here that touches the communicator, for the parallel open), ``packing``
(``packing.npz``), ``tables`` (text tables of particles), ``lammps`` (LAMMPS data
files and dumps in, data lines out), ``lammps_input`` (a LAMMPS input beside a
run), ``export`` (XDMF sidecars, dumps, extended XYZ) and ``network`` (the contact
network for ParaView and OVITO), ``rundir`` (the run directory's layout, its lock
and the atomic writes every file goes through). The map of the house is ARCHITECTURE.md.
"""
