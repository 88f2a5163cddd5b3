"""The set-up without root (docs/install.md): `pip install .[mpi]` into a fresh virtual environment
gives a working mpdem on PyPI's wheels alone (MPICH's `mpich` wheel for mpiexec and libmpi, mpi4py's
wheel on it, h5py's serial wheel), and a 2-rank run and restart there give the digest of the
project's own environment (Debian's MPI and parallel HDF5) for the same config.

The child runs with a bare environment (PATH = the new environment's bin and /usr/bin only, no
PYTHONPATH), so nothing of the project's venv or of Debian's MPI launcher is used; the MPI library
version the child reports says which MPI ran. A validation test: it downloads some 150 MB from PyPI
(cached by pip afterwards) and takes a few minutes.
"""
import os
import subprocess
import sys

import pytest

from helpers import ROOT, mpdem

SETS = ("--set", "pour.N=300", "--set", "box.L_x=8", "--set", "box.L_y=8", "--set", "contact.mu=0.5",
        "--quiet")


def bare(venv, *argv, cwd, timeout=1200):
    env = {"PATH": f"{venv}/bin:/usr/bin:/bin", "HOME": os.environ.get("HOME", "/root"), "LC_ALL": "C.UTF-8"}
    return subprocess.run(list(map(str, argv)), cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


@pytest.mark.validation
def test_pip_install_without_system_mpi_or_parallel_hdf5_runs_two_ranks_to_the_same_bits(tmp_path):
    venv = tmp_path / "venv"
    # made from this venv's python, a venv is made on the base interpreter, with its own pip
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    pip = bare(venv, venv / "bin" / "python", "-m", "pip", "install", "-q", f"{ROOT}[mpi]", cwd=tmp_path)
    assert pip.returncode == 0, pip.stdout[-3000:] + pip.stderr[-3000:]
    probe = bare(venv, "python", "-c", "import h5py, mpi4py.MPI as M; print(h5py.get_config().mpi, "
                 "M.Get_library_version().split()[0])", cwd=tmp_path)
    assert probe.stdout.split() == ["False", "MPICH"], probe.stdout + probe.stderr
    # 2 ranks to step 6000 there, then a restart on 2 ranks to 12000 ...
    run = bare(venv, "mpiexec", "-n", "2", "python", "-m", "mpdem", "run", "--out", "r", *SETS,
               "--set", "run.max_steps=6000", cwd=tmp_path)
    assert run.returncode == 3, run.stdout[-3000:] + run.stderr[-3000:]
    assert "state files are written through rank 0" in run.stderr
    assert "freeing inactive persistent request" not in run.stderr
    again = bare(venv, "mpiexec", "-n", "2", "python", "-m", "mpdem", "restart", "r", "--set", "run.max_steps=12000",
                 "--quiet", cwd=tmp_path)
    assert again.returncode == 3, again.stdout[-3000:] + again.stderr[-3000:]
    theirs = bare(venv, "python", "-m", "mpdem", "info", "r/final.h5", "--digest", cwd=tmp_path)
    # ... equal the straight 2-rank run in the project's environment (mpio, Debian's MPI)
    mpdem("run", "--out", tmp_path / "here", *SETS, "--set", "run.max_steps=12000", n=2, check=3)
    ours = mpdem("info", tmp_path / "here" / "final.h5", "--digest", check=0)
    assert theirs.stdout.split()[-1] == ours.stdout.split()[-1]
