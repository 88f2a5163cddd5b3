"""tools/device_rows.py: sweep rows packed for a lent GPU machine (finished ones as skip marks,
unfinished ones as their newest checkpoint) and what came back put in place."""
import importlib.util
import json
import os
import tarfile
from pathlib import Path

from mpdem.campaign.sweep import Sweep, plan

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("device_rows", ROOT / "tools" / "device_rows.py")
device_rows = importlib.util.module_from_spec(spec)
spec.loader.exec_module(device_rows)


def write(path, text="x"):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def rows(tmp_path):
    table = tmp_path / "t.tsv"
    table.write_text("mu\tseed\n0.5\t1\n0\t2\n0\t3\n")
    return str(table), [r.name for r in sorted(plan([str(table)]), key=lambda r: r.line)]


def test_pack_sends_skip_marks_and_newest_checkpoints_only(tmp_path):
    table, (done, going, fresh) = rows(tmp_path)
    runs = tmp_path / "runs"
    for f in ("config.toml", "packing.npz", "final.h5"):
        write(runs / done / f)
    write(runs / done / "summary.json", json.dumps({"converged": True}))
    write(runs / done / "analysis" / "summary.json", json.dumps({"converged": True}))
    for f in ("config.toml", "thermo.csv", "log.txt", ".lock"):
        write(runs / going / f)
    write(runs / going / "checkpoints" / "ckpt-00001.h5", "old")
    write(runs / going / "checkpoints" / "ckpt-00002.h5", "new")
    into = tmp_path / "devdata" / "rows"
    packed = device_rows.pack(str(runs), [table], None, str(into))
    assert packed == {done: "finished", going: "checkpoint"}
    got = {str(p.relative_to(into)) for p in into.rglob("*") if p.is_file()}
    assert got == {f"{done}/config.toml", f"{done}/analysis/summary.json", f"{going}/config.toml",
                   f"{going}/thermo.csv", f"{going}/log.txt", f"{going}/checkpoints/ckpt-00002.h5"}
    assert (into / going / "checkpoints" / "ckpt-00002.h5").read_text() == "new"
    assert not (into / fresh).exists()
    # the sweep there takes the finished row as done and restarts the other from its checkpoint
    sweep = Sweep(plan([table]), str(into))
    by_name = {r.name: r for r in sweep.rows}
    assert device_rows.finished(sweep.dir(by_name[done])) and sweep.converged(by_name[done])
    assert "restart" in sweep.command(by_name[going])[1]


def tgz(tmp_path, name, files):
    src = tmp_path / "device" / name
    for rel, text in files.items():
        write(src / rel, text)
    out = tmp_path / f"{name}.tgz"
    with tarfile.open(out, "w:gz") as tf:
        tf.add(src, arcname=name)
    return str(out)


def test_unpack_keeps_the_local_config_and_only_the_newest_checkpoint(tmp_path, monkeypatch):
    _, (done, going, fresh) = rows(tmp_path)
    runs = tmp_path / "runs"
    write(runs / going / "config.toml", 'device = "cpu"')
    write(runs / going / "thermo.csv", "short")
    write(runs / going / "checkpoints" / "ckpt-00001.h5", "old")
    write(runs / going / "checkpoints" / "ckpt-00002.h5", "old")
    a = tgz(tmp_path, going, {"config.toml": 'device = "gpu"', "thermo.csv": "longer", ".lock": "device pid",
                              "checkpoints/ckpt-00003.h5": "newest"})
    b = tgz(tmp_path, fresh, {"config.toml": 'device = "gpu"', "summary.json": "{}", "packing.npz": "p",
                              "final.h5": "f", "analysis/summary.json": "{}", "analysis/gofr.csv": "g",
                              "log.txt": "l"})
    monkeypatch.chdir(tmp_path)
    removed, to_commit = device_rows.unpack("runs", [a, b])
    assert (runs / going / "config.toml").read_text() == 'device = "cpu"'
    assert (runs / going / "thermo.csv").read_text() == "longer"
    assert sorted(os.listdir(runs / going / "checkpoints")) == ["ckpt-00003.h5"]
    assert not (runs / going / ".lock").exists()
    assert sorted(removed) == [f"runs/{going}/checkpoints/ckpt-00001.h5", f"runs/{going}/checkpoints/ckpt-00002.h5"]
    assert (runs / fresh / "config.toml").read_text() == 'device = "gpu"'     # none here to keep
    assert to_commit == [f"runs/{going}/config.toml", f"runs/{going}/checkpoints/ckpt-00003.h5",
                         f"runs/{fresh}/config.toml", f"runs/{fresh}/summary.json", f"runs/{fresh}/packing.npz",
                         f"runs/{fresh}/analysis/gofr.csv", f"runs/{fresh}/analysis/summary.json"]
    assert (runs / fresh / "final.h5").exists() and (runs / fresh / "log.txt").exists()
