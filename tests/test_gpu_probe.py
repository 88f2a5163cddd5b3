"""The GPU variants' probe (``tools/gpu_probe.sh``, ``tools/gpu_probe.py``) run dry: every part of the one call
a lent GPU gets, under numba's CUDA simulator (conftest.py) on a 125-sphere table, so that the call works
the first time a GPU is at hand. The timings mean nothing here; the digests, the JSON and the table do.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import tight_lattice

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import gpu_probe  # noqa: E402

DRY = ("row", "entry-all")


@pytest.fixture(scope="module")
def small_table(tmp_path_factory):
    """A jittered 5 x 5 x 5 lattice in contact, moving, its lowest layer the bed: a text table."""
    x, v, _, fixed, _ = tight_lattice(m=5)
    path = tmp_path_factory.mktemp("probe") / "small.txt"
    x[:, :2] += 1.0     # inside the 20 d x 20 d box of the table bench's config
    rows = ["id x y z vx vy vz fixed"] + [" ".join([str(i), *(repr(float(c)) for c in (*x[i], *v[i])), str(fixed[i])])
                                          for i in range(len(x))]
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.fixture(scope="module")
def dry_run(small_table, tmp_path_factory):
    out = tmp_path_factory.mktemp("probe") / "out"
    # two variants (a thread a row; a thread an entry with every switch of the fixed cost) carry the probe's
    # every path; the variants' own bits are test_gpu_engine.py's
    env = {**os.environ, "PY": sys.executable, "SIZE": "small", "VARIANTS": ",".join(DRY)}
    p = subprocess.run(["bash", str(ROOT / "tools" / "gpu_probe.sh"), str(small_table), str(out)], env=env,
                       capture_output=True, text=True, timeout=900)
    return p, out


def test_the_dry_run_measures_every_variant_and_checks_each_digest_against_the_cpus(dry_run):
    p, out = dry_run
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    result = json.loads((out / "probe.json").read_text())
    cpu = result["cpu"]
    assert cpu["atoms"] == 125 and len(cpu["digest"]) == 64 and cpu["check_steps"] == 6
    recs = result["variants"]
    assert [(r["variant"], r["block"]) for r in recs] == [(v, 128) for v in DRY]
    for r in recs:
        assert "failed" not in r, r.get("failed")
        assert r["digest"] == cpu["digest"] and r["same"], (r["variant"], r["block"])
        assert len(r["step_us"]) == 2 and r["step_us_median"] > 0 and r["ns_atom_step"] > 0
        assert len(r["rebuilds"]) == gpu_probe.REBUILDS and all(b["ms"] > 0 for b in r["rebuilds"])
        assert r["sample_ms"] > 0
        assert r["big"]["atoms"] == 125 and r["big"]["ns_atom_step"] > 0
        own = gpu_probe.variant_sets(r["variant"])
        assert r["settings"][-len(own):] == own
    assert result["all_same"] and result["races"] == []
    assert result["anatomy"]["rc"] == 0 and any("run_quiet" in ln for ln in result["anatomy"]["lines"])
    # the table is written, and printed last
    table = (out / "probe.txt").read_text()
    assert table.count("= CPU") == len(recs)
    tail = p.stdout.strip().splitlines()
    assert tail[-1].startswith("numba's CUDA simulator") and "CPU digest after 6 steps" in tail[-2]
    assert "gpu_probe" in (out / "machine.txt").read_text()


def test_a_digest_apart_from_the_cpus_or_between_shapes_is_reported_and_fails():
    def rec(variant, block, digest):
        return {"variant": variant, "block": block, "digest": digest, "step_us_median": 1.0, "ns_atom_step": 1.0,
                "rebuilds": [{"ms": 1.0, "through_host": False}], "kernels": {}, "compile_s": 1.0, "sample_ms": 1.0}
    result = {"cpu": {"digest": "a" * 64, "check_steps": 6, "atoms": 9}, "commit": "x", "repeats": 1, "steps": 1,
              "tiles": "1x1", "big_steps": 1,
              "variants": [rec("row", 128, "a" * 64), rec("row", 256, "a" * 64), rec("entry", 128, "a" * 64),
                           rec("entry", 256, "b" * 64)]}
    gpu_probe.verdicts(result)
    assert not result["all_same"] and result["races"] == ["entry"]
    lines = gpu_probe.table(result)
    assert sum("DIFFERS from the CPU bbbb" in ln for ln in lines) == 1
    assert any(ln.startswith("RACE: the block shapes of entry") for ln in lines)
    result["variants"][3] = {"variant": "entry", "block": 256, "failed": "Traceback\nCudaAPIError: out of memory"}
    gpu_probe.verdicts(result)
    assert not result["all_same"]
    assert any("failed: CudaAPIError: out of memory" in ln for ln in gpu_probe.table(result))
    # a variant the budget left out says so, and is no fault
    result["variants"][3] = {"variant": "entry", "block": 256, "skipped": "the budget: 400 s spent of 420"}
    gpu_probe.verdicts(result)
    assert result["all_same"] and any("skipped: the budget" in ln for ln in gpu_probe.table(result))


def test_a_process_that_dies_leaves_its_variant_failed_and_a_new_one_goes_on(tmp_path):
    """``drive``: a child that dies at a variant (a GPU fault loses the process's context) leaves that one
    recorded as failed with its output and why; the next child starts after it; one stopped past the budget
    says so. Every key gets one record, in order."""
    path = str(tmp_path / "v.jsonl")
    keys = [("row", 128), ("row", 256), ("entry", 128), ("entry", 256), ("row-all", 128), ("row-all", 256)]
    calls = []

    def child(variants, shapes, deadline, longest, timeout):
        calls.append((variants, shapes))
        done = {(r["variant"], r["block"]) for r in gpu_probe.read_records(path)}
        for v in variants:
            for b in shapes:
                if (v, b) in done:
                    continue
                if (v, b) == ("entry", 128):
                    return 1, "Traceback\nCudaAPIError: an illegal memory access"
                if (v, b) == ("row-all", 128):
                    return None, "still at it"
                gpu_probe.append_record(path, {"variant": v, "block": b, "wall_s": 1.0})
        return 0, ""

    recs = gpu_probe.drive(keys, path, child, deadline=1e18, grace=1.0)
    assert [(r["variant"], r["block"]) for r in recs] == keys
    assert recs[2]["failed"] == "its process ended with status 1\nTraceback\nCudaAPIError: an illegal memory access"
    assert recs[4]["failed"] == "ran past the budget and was stopped\nstill at it"
    assert all("failed" not in r for i, r in enumerate(recs) if i not in (2, 4))
    # the second child starts at the variant after the one that died, the third after the one stopped
    assert calls == [(["row", "entry", "row-all"], [128, 256]), (["entry", "row-all"], [128, 256]),
                     (["row-all"], [256])]


@pytest.mark.parametrize("args, what", [
    (["--tiles", "7"], "--tiles 7: accepted AxB"),
    (["--variants", "row,fast"],
     "--variants row,fast: accepted a comma-separated choice of default, entry-all-rebuild-hostsort, "
     "lanes4-all-rebuild-hostsort, lanes4-warp-rebuild-hostsort, default-warp, lanes8-all-rebuild-hostsort, "
     "lanes2-all-rebuild-hostsort, lanes4-all-rebuild-hostsort-r128, default-r128, row, row-all"),
    (["--shapes", "100"], "--shapes 100: accepted comma-separated powers of two"),
    (["--steps", "0"], "--steps 0: accepted a whole number >= 1"),
])
def test_bad_arguments_are_one_clear_error(small_table, tmp_path, args, what, capsys):
    with pytest.raises(SystemExit) as e:
        gpu_probe.main(["all", str(small_table), str(tmp_path), *args])
    assert e.value.code == 2 and what in capsys.readouterr().err
    with pytest.raises(SystemExit):
        gpu_probe.main(["all", str(tmp_path / "none.txt"), str(tmp_path)])
    assert "TABLE" in capsys.readouterr().err and not (tmp_path / "probe.json").exists()


def test_a_variants_name_means_the_same_switches_whatever_the_configs_defaults():
    """Every switch a variant sets is in BASE, so a variant's settings name each one (the defaults moved on
    2026-11-28: "row" must stay the old engine); "default" alone takes the config's."""
    from mpdem.bench import table_config
    set_anywhere = {k for v in gpu_probe.VARIANTS.values() for k in v}
    assert set_anywhere <= set(gpu_probe.BASE)
    assert gpu_probe.variant_sets("default") == []
    cfg = table_config(gpu_probe.variant_sets("row"))
    assert (cfg.engine.gpu_pinned, cfg.engine.gpu_drift, cfg.engine.gpu_rebuild, cfg.engine.gpu_samples) == (
        False, "apart", "host", "host")
    # a variant's own switches come after BASE's and win
    cfg = table_config(gpu_probe.variant_sets("row-all-rebuild-hostsort"))
    assert (cfg.engine.gpu_pinned, cfg.engine.gpu_rebuild, cfg.engine.gpu_sort) == (True, "launch", "host")
    # the next GPU measures the forces a thread an entry with the rebuilds inside the launches first
    assert list(gpu_probe.VARIANTS)[:2] == ["default", "entry-all-rebuild-hostsort"]
    cfg = table_config(gpu_probe.variant_sets("entry-all-rebuild-hostsort"))
    assert (cfg.engine.gpu_threads, cfg.engine.gpu_pinned, cfg.engine.gpu_rebuild, cfg.engine.gpu_sort) == (
        "entry", True, "launch", "host")
    # then lanes of a warp a row, which need the pinned launches
    assert list(gpu_probe.VARIANTS)[2:7] == ["lanes4-all-rebuild-hostsort", "lanes4-warp-rebuild-hostsort",
                                             "default-warp", "lanes8-all-rebuild-hostsort",
                                             "lanes2-all-rebuild-hostsort"]
    cfg = table_config(gpu_probe.variant_sets("lanes8-all-rebuild-hostsort"))
    assert (cfg.engine.gpu_threads, cfg.engine.gpu_pinned, cfg.engine.gpu_rebuild) == ("lanes8", True, "launch")
