"""Helpers shared by the MPI tests (imported as ``mpi_helpers``)."""
import hashlib
import json
import os
import tempfile

from mpi4py import MPI

from mpdem.driver.simulation import Run

PILE = ["box.L_x=5.0", "box.L_y=5.0", "pour.N=200", "pour.phi_i=0.3", "pour.K0=5.0",
        "output.progress_every=100000", "stop.sample_interval=0.01"]

# one-rank digests already computed in this pytest session, by reference_key (rank 0 only)
REFERENCES = {}
# a JSON file of one-rank digests by reference_key, shared by the pytest runs of one `make test-mpi` (2, 3 and 4
# ranks run the same references): the Makefile names it and removes it first, so it never outlives the code
SHARED = os.path.abspath(os.environ["MPDEM_TEST_REFERENCES"]) if os.environ.get("MPDEM_TEST_REFERENCES") else None


def shared_dir(comm):
    return comm.bcast(tempfile.mkdtemp() if comm.Get_rank() == 0 else None)


def run(cfg, out, comm):
    r = Run.new(cfg, out, comm, quiet=True)
    r.run()
    return r, r.finish()


def reference_key(cfg):
    """All that a one-rank run's result depends on: every config value, with each input file
    (``run.initial_file``, ``bed.file``) named by its bytes rather than by its path, which
    differs from test to test (each writes its files in its own directory)."""
    values = dict(cfg.values)
    for k, v in values.items():
        if k.endswith("file") and v:
            with open(v, "rb") as fh:
                values[k] = "sha256:" + hashlib.sha256(fh.read()).hexdigest()
    return repr(sorted(values.items()))


def shared_references():
    """The digests of ``SHARED`` by reference_key (none when it is unset or not written yet)."""
    if not SHARED or not os.path.exists(SHARED):
        return {}
    with open(SHARED) as fh:
        return json.load(fh)


def share_reference(key, digest):
    """Add one digest to ``SHARED`` (rewritten whole, then renamed: a reader never sees half a file)."""
    if not SHARED:
        return
    known = shared_references()
    known[key] = digest
    os.makedirs(os.path.dirname(SHARED), exist_ok=True)
    with open(SHARED + ".tmp", "w") as fh:
        json.dump(known, fh)
    os.replace(SHARED + ".tmp", SHARED)


def serial_digest(cfg, out, comm):
    """The one-rank digest of ``cfg``, computed on rank 0 (in ``out``) once per pytest session and
    shared with every rank; a test that asks again for the same run gets the stored digest. Under
    ``make test-mpi`` the digests are also kept in the file ``MPDEM_TEST_REFERENCES`` names, so that the
    3- and 4-rank pytest runs take the references the 2-rank run computed instead of running them again.

    Collective-safe: only rank 0 looks in ``REFERENCES`` and runs, every other rank just receives
    (one bcast on every path), so all ranks take the same collective calls whether the reference
    is new or not. A failure on rank 0 fails the test on every rank instead of leaving them waiting.
    The reference runs with the threads in force on rank 0 (one: tests that configure more restore
    it before asking)."""
    digest = error = None
    if comm.Get_rank() == 0:
        try:
            key = reference_key(cfg)
            if key not in REFERENCES:
                REFERENCES.update(shared_references())
            if key not in REFERENCES:
                _, s = run(cfg, out, MPI.COMM_SELF)
                REFERENCES[key] = s["digest"]
                share_reference(key, s["digest"])
            digest = REFERENCES[key]
        except BaseException as e:
            error = e
    digest, failed = comm.bcast((digest, None if error is None else repr(error)))
    if error is not None:
        raise error
    if failed is not None:
        raise RuntimeError(f"the one-rank reference failed on rank 0: {failed}")
    return digest
