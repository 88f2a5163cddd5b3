"""Beds made once (``bedcache``): the bed read back is the bed made, bit for bit; another value of
a bed-making key is another bed; a damaged file is made again; the cache can be turned off."""
import numpy as np

from mpdem import bedcache, build, config

# a bed of 72 spheres settled: a few seconds
SMALL = ["run.max_steps=1", "box.L_x=3", "box.L_y=3"]


def cfg_of(*sets):
    return config.load(None, [*SMALL, *sets])


def test_a_kept_bed_is_the_made_bed_bit_for_bit(tmp_path, monkeypatch):
    monkeypatch.setenv(bedcache.ENV, str(tmp_path))
    cfg = cfg_of()
    made = build.make_bed(cfg)
    first = bedcache.made_bed(cfg)
    assert [p.name for p in tmp_path.iterdir()] == [f"bed-{bedcache.key(cfg)}.npz"]
    kept = bedcache.made_bed(cfg)
    assert "kept from its first making" in kept.note and kept.note.startswith(made.note)
    for b in (first, kept):
        assert b.x.dtype == made.x.dtype and b.x.tobytes() == made.x.tobytes()


def test_each_bed_making_value_and_the_seed_is_its_own_bed(tmp_path, monkeypatch):
    monkeypatch.setenv(bedcache.ENV, str(tmp_path))
    base = bedcache.key(cfg_of())
    others = [cfg_of("bed.seed=7"), cfg_of("run.seed=3"), cfg_of("bed.settle_time=30"), cfg_of("box.L_x=4"),
              cfg_of("bed.gap=3.5")]
    keys = {bedcache.key(c) for c in others}
    assert base not in keys and len(keys) == len(others)
    # the warnings' bounds and the wall make no other bed
    assert bedcache.key(cfg_of("bed.density_max=2.0", "bed.wall=true")) == base
    # run.seed is the bed's seed only while bed.seed is unset
    assert bedcache.key(cfg_of("bed.seed=7", "run.seed=3")) == bedcache.key(cfg_of("bed.seed=7"))


def test_a_damaged_file_is_made_again_and_replaced(tmp_path, monkeypatch):
    monkeypatch.setenv(bedcache.ENV, str(tmp_path))
    cfg = cfg_of()
    made = bedcache.made_bed(cfg)
    path = tmp_path / f"bed-{bedcache.key(cfg)}.npz"
    path.write_bytes(path.read_bytes()[:100])
    again = bedcache.made_bed(cfg)
    assert "kept" not in again.note and again.x.tobytes() == made.x.tobytes()
    assert bedcache._read(path).x.tobytes() == made.x.tobytes()
    np.savez(path, x=np.zeros((4, 2)), note=np.array("not a bed"))
    assert bedcache._read(path) is None


def test_off_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv(bedcache.ENV, "off")
    assert bedcache.directory() is None
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    bedcache.made_bed(cfg_of())
    assert not any(tmp_path.rglob("*.npz"))
