"""``mpdem sweep``: tables read as the cluster helper reads them, bad input refused
before any run, and real rows run, stopped, resumed bit-identically and skipped."""
import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from mpdem import config
from mpdem.campaign import sweep
from mpdem.io.checkpoint import digest, read_state

from helpers import child_env, fake_segment_mpdem, mpdem, mpdem_argv

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT / "analysis" / "sweeps" / "dev"
# a small pile that settles in seconds and still has a bulk region to analyse
SMALL = ["pour.N=300", "box.L_x=4", "box.L_y=4", "run.max_steps=2000000"]


def tables():
    return sorted(ROOT.glob("analysis/sweeps/**/*.tsv")) + [ROOT / "jobs" / "sweep.example.tsv"]


def test_rows_are_named_and_set_as_the_cluster_helper_does(tmp_path):
    """Every row of every shipped table: the same run directory and --set items as
    ``jobs/mpdem-segment.sh --sweep``, so a sweep moves between cluster and laptop."""
    e = child_env({"MPDEM_CMD": fake_segment_mpdem(tmp_path / "fake-mpdem.sh", tmp_path / "calls")}, clean=True)
    for t in tables():
        rows = sweep.read_table(str(t))
        (tmp_path / "calls").write_text("")
        for r in rows:
            p = subprocess.run(["bash", str(ROOT / "jobs/mpdem-segment.sh"), "--sweep", str(t), str(r.line),
                                "root", ""], env=e, capture_output=True, text=True, cwd=tmp_path)
            assert p.returncode == 0, (t, r.line, p.stderr)
        calls = [c.split() for c in (tmp_path / "calls").read_text().splitlines()]
        assert [c[2] for c in calls] == [f"root/{r.name}" for r in rows], t
        assert [[c[k + 1] for k in range(len(c)) if c[k] == "--set"] for c in calls] == [r.sets for r in rows], t


def test_the_development_tables():
    """analysis/sweeps/dev: N = 2000 in a 10 d box; the issue's mu x epsilon x 3 seeds, k_n ladder
    for two families with 2 seeds, Fig. 7b's three other families to 2e7 with 2 seeds, phi_i ladder with 2
    seeds, and three of those rows again under the translational stop rule (spinners.tsv); no run directory
    shared."""
    rows = sweep.plan(sorted(str(t) for t in DEV.glob("*.tsv")), str(DEV / "dev.toml"))
    cfgs = {r.name: config.load(str(DEV / "dev.toml"), r.sets).values for r in rows}
    assert len(cfgs) == len(rows) == 60 + 16 + 16 + 12 + 3
    assert all(v["pour.N"] == 2000 and v["box.L_x"] == v["box.L_y"] == 10 for v in cfgs.values())
    by_table = {}
    for r in rows:
        by_table.setdefault(Path(r.table).name, []).append(cfgs[r.name])
    sets = {}
    for v in by_table["fig2-4.tsv"]:
        sets.setdefault((v["contact.mu"], v["contact.epsilon"]), set()).add(v["run.seed"])
    assert set(sets) == {(m, e) for m in (0, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 1, 2, 10) for e in (0.88, 0.26)}
    assert all(len(s) == 3 for s in sets.values())
    fam = {}
    for v in by_table["fig7.tsv"]:
        by_kn = fam.setdefault((v["contact.mu"], v["contact.epsilon"]), {})
        by_kn.setdefault(v["contact.k_n"], set()).add(v["run.seed"])
    assert set(fam) == {(0.0, 0.88), (0.5, 0.88)}
    assert all(sorted(k) == [2e5, 2e6, 2e7, 2e8] and all(len(s) == 2 for s in k.values()) for k in fam.values())
    fam = {}
    for v in by_table["fig7b.tsv"]:
        by_kn = fam.setdefault((v["contact.mu"], v["contact.epsilon"], v["stop.energy"]), {})
        by_kn.setdefault(v["contact.k_n"], set()).add(v["run.seed"])
    # [0.5, 0.26] at 2e5 is fig2-4.tsv's (seeds 1-3); mu = 10 on the translational energy from 2e5 on
    assert fam == {(0.5, 0.5, "total"): {2e5: {2, 3}, 2e6: {2, 3}, 2e7: {2, 3}},
                   (0.5, 0.26, "total"): {2e6: {2, 3}, 2e7: {2, 3}},
                   (10.0, 0.26, "translational"): {2e5: {2, 3}, 2e6: {2, 3}, 2e7: {2, 3}}}
    assert sorted({v["pour.phi_i"] for v in by_table["fig9.tsv"]}) == [0.02, 0.05, 0.08, 0.13, 0.20, 0.30]
    # spinners.tsv: rows of the other tables, the stop rule on the translational energy the only change
    others = [v for t, vs in by_table.items() if t != "spinners.tsv" for v in vs]
    assert len(by_table["spinners.tsv"]) == 3
    for v in by_table["spinners.tsv"]:
        assert v["stop.energy"] == "translational"
        assert sum({**v, "stop.energy": "total"} == o for o in others) == 1
    # the cheapest rows first: the stiffest last
    assert [cfgs[r.name]["contact.k_n"] for r in rows[-4:]] == [2e8] * 4
    assert rows[0].cost == min(r.cost for r in rows)


def test_the_paper_tables():
    """analysis/sweeps/paper (issue 23): the paper's height at a quarter of its area, the paper's size,
    and the development tables' k_n = 2e5 rows at mu = 0 and 0.5 again with their own seeds."""
    P = DEV.parent / "paper"
    dev = {r.name: r.sets for r in sweep.plan(sorted(str(t) for t in DEV.glob("*.tsv")), str(DEV / "dev.toml"))}
    for table, toml, n, L, rows in (("height", "height", 5000, 10, 6), ("size", "size", 20000, 20, 9),
                                    ("dev2e5", None, 2000, 10, 13), ("dev-stiff", None, 2000, 10, 7)):
        cfg = str(P / f"{toml}.toml") if toml else str(DEV / "dev.toml")
        plan = sweep.plan([str(P / f"{table}.tsv")], cfg)
        assert len(plan) == rows
        for r in plan:
            v = config.load(cfg, r.sets).values
            assert v["pour.N"] == n and v["box.L_x"] == v["box.L_y"] == L
            assert v["contact.k_n"] == 2e5 or table == "dev-stiff"
            assert v["pour.phi_i"] == 0.13 and v["contact.mu"] in (0, 0.1, 0.5, 1)
            if table.startswith("dev"):
                # the same row (so the same bits) as in the development tables
                assert dev[r.name] == r.sets
    size = [config.load(str(P / "size.toml"), r.sets).values
            for r in sweep.plan([str(P / "size.tsv")], str(P / "size.toml"))]
    assert sum(v["contact.mu"] == 0 and v["contact.epsilon"] == 0.88 for v in size) == 3
    assert sum(v["contact.mu"] == 0.5 for v in size) == 2


def test_a_restart_takes_the_sweeps_device(tmp_path):
    """A row begun on a GPU machine (its config says engine.device = "gpu") goes on elsewhere when the
    sweep is given engine.device: the restart is told the device; without it the run keeps its own."""
    row = sweep.Row("t.tsv", 1, ["contact.mu=0.5", "run.seed=1"], "mu0.5_s1")
    (tmp_path / row.name / "checkpoints").mkdir(parents=True)
    (tmp_path / row.name / "checkpoints" / "ckpt-00000.h5").write_bytes(b"")
    stage, argv = sweep.Sweep([row], str(tmp_path), sets=["engine.device=cpu"]).command(row)
    assert stage == "run" and argv[argv.index("restart") + 2:argv.index("restart") + 4] == ["--device", "cpu"]
    _, argv = sweep.Sweep([row], str(tmp_path), sets=['engine.device="gpu"', "contact.mu=0"]).command(row)
    assert argv[argv.index("--device") + 1] == "gpu"
    _, argv = sweep.Sweep([row], str(tmp_path)).command(row)
    assert "restart" in argv and "--device" not in argv


@pytest.mark.parametrize("text, match", [
    ("mu\tcolour\n0.5\tred\n", "unknown column 'colour'"),
    ("mu\tcontact.k_x\n0.5\t1\n", "column 'contact.k_x' is no config key"),
    ("mu\tseed\n0.5\n", "row 1: 1 values for 2 columns"),
    ("mu\tseed\n0.5\t1\n0.5\t1\n", "row 2 of .* and row 1 of .* both make run directory mu0.5_s1"),
    ("mu\tseed\n0.5\t1\n-3\t2\n", r"row 2 \(mu-3_s2\): .*contact.mu"),
    ("mu\tseed\n0.5\ta/b\n", "row 1: value 'a/b' of seed"),
    ("# only a comment\n", "no header line"),
    ("mu\tseed\n", "a header but no rows"),
    ("mu\trun.initial_file\n0.5\tmissing.txt\n", r"row 1 .*run\.initial_file missing\.txt: no such file"),
])
def test_bad_tables_are_refused_before_any_run(tmp_path, text, match):
    import re
    t = tmp_path / "t.tsv"
    t.write_text(text)
    p = mpdem("sweep", t, "--out", tmp_path / "out", clean=True)
    assert p.returncode == 1
    assert p.stderr.startswith("mpdem: error: sweep") and re.search(match, p.stderr), p.stderr
    assert str(t) in p.stderr
    assert not (tmp_path / "out").exists()


def test_default_jobs_fill_the_cores(monkeypatch):
    monkeypatch.setattr(sweep, "cores", lambda: 8)
    assert [sweep.default_jobs(r, t) for r, t in ((1, 1), (2, 1), (2, 2), (3, 1), (16, 1))] == [8, 4, 2, 2, 1]


def wait_for(pred, timeout, what):
    t0 = time.monotonic()
    while not pred():
        assert time.monotonic() - t0 < timeout, f"timed out waiting for {what}"
        time.sleep(0.2)


def damaged_state_file(path):
    """A state file of the sweep's box (4 x 4) and count (300 mobile spheres on 4 bed spheres) whose
    attributes read whole but one of whose positions changed after its checksum was written."""
    import h5py
    import numpy as np
    from helpers import simple_cubic, write_crystal
    x, L = simple_cubic(4, 19, 1.0)
    fixed = (np.arange(len(x)) < 4).astype(np.uint8)
    write_crystal(path, x, fixed, L)
    with h5py.File(path, "r+") as f:
        d = next(f[g]["x"] for g in f if isinstance(f[g], h5py.Group) and "x" in f[g])
        d[0, 0] += 0.25


@pytest.mark.validation
def test_a_sweep_runs_stops_resumes_and_skips(tmp_path):
    """Two real frictional rows and one that fails when it runs (an initial file damaged on disk:
    its attributes, all the plan reads, are whole; its data fail their checksum): the failure is
    reported with its reason while the others go on; SIGINT stops a running row with a
    checkpoint (exit 75); the next sweep restarts it from there and it ends bit-identical
    to a straight run; a third sweep finds everything finished and runs nothing."""
    t = tmp_path / "t.tsv"
    t.write_text("# a pile\nmu\tseed\n0.5\t1\n")
    damaged_state_file(tmp_path / "damaged.h5")
    broken = tmp_path / "broken.tsv"
    broken.write_text("mu\tseed\trun.initial_file\n0.5\t2\tdamaged.h5\n")
    out = tmp_path / "runs"
    args = ["sweep", t, broken, "--out", out, "--jobs", "1", "--progress", "1", "--collect", tmp_path / "collect"]
    for s in SMALL:
        args += ["--set", s]
    run1 = out / "mu0.5_s1"
    p = subprocess.Popen(mpdem_argv(*args), env=child_env(clean=True), cwd=tmp_path, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True)
    try:
        # the sweep runs cheapest first (equal cost: table order), one at a time
        wait_for(lambda: (run1 / "thermo.csv").exists() and len((run1 / "thermo.csv").read_text().splitlines()) > 3,
                 300, "the first row to make progress")
        p.send_signal(signal.SIGINT)
        text, _ = p.communicate(timeout=300)
    finally:
        p.kill()
    assert p.returncode == 75, text
    assert "SIGINT: stopping the running rows" in text and "mu0.5_s1: stopped (checkpoint written)" in text
    assert list((run1 / "checkpoints").glob("*.h5")) and not (run1 / "final.h5").exists()
    assert not list(out.glob("mu0.5_s2*"))                          # never started
    assert not (tmp_path / "collect").exists()                     # a stopped sweep does not collect

    q = mpdem(*args, clean=True, cwd=tmp_path, timeout=900)
    assert q.returncode == 1, q.stdout + q.stderr              # a row failed; the other finished
    assert "mu0.5_s1: restart from its checkpoint" in q.stdout
    fail = [ln for ln in q.stdout.splitlines() if ln.startswith("sweep: failed: mu0.5_s2_initial_file")]
    assert fail and "damaged.h5" in fail[0] and "run exit 1" in fail[0], q.stdout
    assert "1/2 finished (0 not converged), 0 running, 1 failed" in q.stdout
    summ = json.loads((run1 / "analysis" / "summary.json").read_text())
    assert summ["converged"] and summ["params"]["contact.mu"] == 0.5
    assert (run1 / "packing.npz").exists()          # the row's packing, kept for later analyses
    assert (tmp_path / "collect" / "runs.csv").exists()

    ref = tmp_path / "ref"
    one = SMALL + ["contact.mu=0.5", "run.seed=1"]
    r = mpdem("run", "--out", ref, "--quiet", *sum((["--set", s] for s in one), []),
              clean=True)
    assert r.returncode == 0, r.stderr
    assert digest(read_state(str(run1 / "final.h5"))[0]) == digest(read_state(str(ref / "final.h5"))[0])

    # everything finished (the broken row fails again, and alone)
    before = (run1 / "sweep.log").read_text()
    s = mpdem(*args[:2], *args[3:], clean=True, cwd=tmp_path, timeout=300)   # without the broken table
    assert "1 already finished" in s.stdout, s.stdout
    assert (run1 / "sweep.log").read_text() == before


def test_a_row_whose_count_disagrees_with_its_initial_file_is_refused_before_any_run(tmp_path):
    """The sweep resolves each row as the run will (``initial.config_for``): a row's pour.N that is not its
    initial file's is refused at the plan, not when the row starts hours later; a row that agrees is
    costed by the file's count."""
    import numpy as np
    from mpdem.errors import SweepError
    from helpers import SQUEEZE, simple_cubic, write_crystal
    x, L = simple_cubic(4, 5, SQUEEZE)
    fixed = (x[:, 2] < 1).astype(np.uint8)
    h5 = tmp_path / "pile.h5"
    write_crystal(h5, x, fixed, L)
    n = int((fixed == 0).sum())
    t = tmp_path / "t.tsv"
    t.write_text(f"pour.N\tseed\n{n}\t1\n7\t2\n")
    with pytest.raises(SweepError, match=rf"row 2 .*pour\.N = 7, but run\.initial_file .*pile\.h5 has {n} mobile"):
        sweep.plan([str(t)], None, [f"run.initial_file={h5}", "contact.mu=0"])
    t.write_text("seed\n1\n")
    row, = sweep.plan([str(t)], None, [f"run.initial_file={h5}", "contact.mu=0"])
    assert row.cost == n / 1e-4


@pytest.mark.parametrize("left", ["final.h5", "checkpoints/ckpt-00003.h5"])
def test_a_begun_row_is_not_judged_by_an_initial_file_it_will_not_read(tmp_path, left):
    """A row that is finished or has a checkpoint is analysed or restarted, never started from its initial
    file again: the plan goes on where that file has gone (moved, another machine); a row that would
    start from it is still refused before any run."""
    from mpdem.errors import SweepError
    t = tmp_path / "t.tsv"
    t.write_text("seed\n1\n2\n")
    out = tmp_path / "runs"
    sets = [f"run.initial_file={tmp_path / 'gone.h5'}", "contact.mu=0"]
    with pytest.raises(SweepError, match=r"row 1 \(s1\): run\.initial_file .*gone\.h5: no such file"):
        sweep.plan([str(t)], None, sets, out=str(out))
    for name in ("s1", "s2"):
        (out / name / left).parent.mkdir(parents=True)
        (out / name / left).write_bytes(b"")
    assert [r.name for r in sweep.plan([str(t)], None, sets, out=str(out))] == ["s1", "s2"]
    # a begun row is costed by the count its run recorded (the file's), not the sweep's config
    (out / "s2" / "config.toml").write_text(config.load_run_config(None, ["pour.N=40", "contact.mu=0"]).to_toml())
    first, second = sweep.plan([str(t)], None, sets, out=str(out))
    assert (first.name, first.cost, second.name) == ("s2", 40 / 1e-4, "s1")
    (out / "s2" / left).unlink()
    with pytest.raises(SweepError, match=r"row 2 \(s2\): run\.initial_file"):
        sweep.plan([str(t)], None, sets, out=str(out))
