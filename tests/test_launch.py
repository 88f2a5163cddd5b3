"""Launch mistakes give one clear error and never hang."""
import os
import re
import subprocess
import sys
from pathlib import Path

from helpers import mpdem

MPIEXEC = Path(sys.executable).parent / "mpiexec"
# os.environ, not the C environment: tests that call mpdem's main() in this
# process have made it an MPI singleton, whose PMIx variables would confuse a
# child mpiexec (it then exits 1 without a word)
ENV = dict(os.environ)


def test_mpi4py_of_another_mpi_is_detected(tmp_path):
    # what a process started by a foreign mpiexec sees: a launcher size > 1, a world of 1
    p = mpdem("run", "--set", "run.max_steps=1", "--out", tmp_path / "r",
              env={"OMPI_COMM_WORLD_SIZE": "2", "PMI_SIZE": "2"}, timeout=120)
    assert p.returncode == 1
    assert "mpi4py sees a world of size 1" in p.stderr


def test_error_on_ranks_exits_all_ranks(tmp_path):
    # several ranks with a bad value: every rank reports and the job ends (no hang)
    p = mpdem("run", "--set", "contact.mu=-1", "--out", tmp_path / "r", n=2, timeout=120)
    assert p.returncode != 0
    assert "contact.mu = -1" in p.stderr


def on_two_ranks(path, text):
    """Write the script ``text`` to ``path`` and run it under ``mpiexec -n 2`` (a hang fails at 120 s)."""
    path.write_text(text)
    return subprocess.run([str(MPIEXEC), "-n", "2", sys.executable, str(path)],
                          capture_output=True, text=True, timeout=120, env=ENV)


def test_exception_on_one_rank_aborts_all_ranks(tmp_path):
    """Rank 1 fails while rank 0 waits in a collective: all ranks end, with the message."""
    p = on_two_ranks(tmp_path / "one_rank_fails.py",
        "import sys\n"
        "import mpdem.__main__ as cli\n"
        "def handler(args, net):\n"
        "    if net.rank == 1:\n"
        "        raise RuntimeError('boom on rank 1')\n"
        "    net.barrier()  # without the abort, rank 0 would wait here for ever\n"
        "    return 0\n"
        "cli.cmd_info = handler\n"
        "sys.exit(cli.main(['info', 'nothing.h5']))\n")
    assert p.returncode != 0
    assert "boom on rank 1" in p.stderr and "internal error on rank 1" in p.stderr


def test_wrapper_unbinds_ranks_that_ask_for_threads():
    """Open MPI binds each of 2 ranks to one core; the venv's mpiexec lifts that for --threads T > 1
    (the threads of a rank need cores), and keeps it for one thread or a binding given by the user."""
    import pytest
    if os.cpu_count() < 2 or "mpiexec.openmpi" not in MPIEXEC.read_text():
        pytest.skip("needs Open MPI (it binds ranks to cores) and 2 cores to see a binding")
    # each rank's answer tagged: Open MPI's output forwarding may join two ranks' lines ("22")
    probe = ["-c", "import os; print(f'cores={len(os.sched_getaffinity(0))};')"]

    def cores(*args, mpi=()):
        p = subprocess.run([str(MPIEXEC), *mpi, "-n", "2", sys.executable, *probe, *args],
                           capture_output=True, text=True, timeout=120, env=ENV)
        assert p.returncode == 0, p.stderr
        return sorted(int(v) for v in re.findall(r"cores=(\d+);", p.stdout))

    assert cores() == [1, 1]
    assert cores("--threads", "2") == [os.cpu_count()] * 2
    assert cores("--threads=2") == [os.cpu_count()] * 2
    assert cores("--threads", "2", mpi=("--bind-to", "core")) == [1, 1]


def test_threads_warnings_name_binding_and_oversubscription(monkeypatch):
    from mpdem.__main__ import threads_warnings
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "2")
    assert threads_warnings(2, 4) == []
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    bound = threads_warnings(2, 1)
    assert len(bound) == 2 and "--bind-to none" in bound[0] and "OMP_WAIT_POLICY=PASSIVE" in bound[1]
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "4")
    over = threads_warnings(2, 4)
    assert len(over) == 2 and "4 rank(s) x 2 threads on this node's 4 cores" in over[0]
    assert "waiting threads sleep" in over[1]
    # one thread never oversubscribes; the passive policy is set only when threads outnumber cores
    from mpdem import threads
    assert threads.oversubscribed(2, 4) and not threads.oversubscribed(1, 4)
    monkeypatch.setenv("OMPI_COMM_WORLD_LOCAL_SIZE", "2")
    assert not threads.oversubscribed(1, 1) and threads.oversubscribed(2, 1) and not threads.oversubscribed(2, 4)
    assert threads.oversubscribed(3, 4)


def test_the_program_ignores_stop_signals_once_its_work_is_done(tmp_path):
    """A stop signal while ``python -m mpdem`` shuts down (MPI finalize; a batch system's
    early warning reaching a run that has just finished) must not turn its exit status into a
    death by signal (a job chain read exit 138 as an error); an in-process caller gets its
    own handlers back."""
    import signal
    from mpdem.__main__ import main
    stops = (signal.SIGTERM, signal.SIGUSR1)
    old = {s: signal.getsignal(s) for s in stops}
    try:
        import pytest
        with pytest.raises(SystemExit):
            main(["info", str(tmp_path / "missing.h5")])
        assert all(signal.getsignal(s) == old[s] for s in stops)
        with pytest.raises(SystemExit):
            main(["info", str(tmp_path / "missing.h5")], program=True)
        assert all(signal.getsignal(s) == signal.SIG_IGN for s in stops)
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def test_an_uncaught_exception_in_a_script_ends_every_rank(tmp_path):
    """Library use (issue 24): a script that calls mpdem under mpiexec and fails on one rank while
    the other waits in a collective ends, on every rank, with the message."""
    p = on_two_ranks(
        tmp_path / "script_fails.py",
        "import mpdem\n"
        "from mpdem.parallel import world\n"
        "net = world()\n"
        "if net.rank == 1:\n"
        "    mpdem.load_config(**{'contact.mu': -1.0})\n"
        "net.barrier()  # without the abort, rank 0 would wait here for ever\n")
    assert p.returncode != 0
    assert "contact.mu = -1.0" in p.stderr and "uncaught exception on rank 1 of 2" in p.stderr


def test_the_mpi_test_suite_stops_at_the_first_failure_on_any_rank(tmp_path):
    """mpi_tests/conftest.py: a test that fails on rank 1 while rank 0 waits in a collective ends
    both ranks with the failure shown, instead of hanging (issue 24)."""
    import shutil
    shutil.copy(Path(__file__).parents[1] / "mpi_tests" / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_fails.py").write_text(
        "def test_rank_one_fails(comm):\n"
        "    assert comm.Get_rank() != 1, 'rank 1 says no'\n"
        "    comm.Barrier()\n"
        "def test_never_reached(comm):\n"
        "    comm.Barrier()\n")
    p = subprocess.run([str(MPIEXEC), "-n", "2", sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        str(tmp_path)], capture_output=True, text=True, timeout=120, env=ENV, cwd=tmp_path)
    assert p.returncode != 0
    out = p.stdout + p.stderr
    assert "test_rank_one_fails failed on rank 1 of 2" in out and "rank 1 says no" in out


def test_binding_takes_one_hyperthread_of_every_core_before_a_second():
    """``threads.cores_first``: cores numbered before their siblings (x86 Linux: cpu i and i + 4 share a
    core) stay in order; threads of a core numbered side by side (POWER, some ARM: 0-1, 2-3, ...) are
    taken one a core first; a cpu whose siblings are unknown is a core of its own."""
    from mpdem.threads import cores_first
    x86 = {c: sorted({c % 4, c % 4 + 4}) for c in range(8)}
    assert cores_first(range(8), x86.get) == list(range(8))
    side = {c: [c - c % 2, c - c % 2 + 1] for c in range(8)}
    assert cores_first(range(8), side.get) == [0, 2, 4, 6, 1, 3, 5, 7]
    # a share of the machine (an affinity of cpus 2-5): still a whole core for each of the first two
    assert cores_first([2, 3, 4, 5], side.get) == [2, 4, 3, 5]
    assert cores_first([5, 3, 9], lambda c: [c]) == [3, 5, 9]
