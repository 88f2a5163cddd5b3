"""tools/device_slim.sh: the result packings, checkpoints and final states kept from travelling to a lent GPU machine
for one call (the device sends tracked and untracked-not-ignored files, at most 64 MiB), and put back.

Run on a clone of this checkout: `on` leaves them on disk but neither tracked nor unignored, so they
would not travel; `off` gives back the index and the .gitignore files exactly (a clean status)."""
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def git(repo, *args):
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True, text=True).stdout


def slim(repo, what):
    return subprocess.run(["bash", "tools/device_slim.sh", what], cwd=repo, capture_output=True, text=True)


def travelling(repo):
    """Paths that would travel: tracked, and untracked that git does not ignore."""
    out = git(repo, "ls-files") + git(repo, "ls-files", "--others", "--exclude-standard")
    return set(out.split("\n")) - {""}


def test_on_keeps_the_packings_at_home_and_off_gives_everything_back(tmp_path):
    repo = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", "--local", str(ROOT), str(repo)], check=True)
    shutil.copy(ROOT / "tools" / "device_slim.sh", repo / "tools" / "device_slim.sh")   # the one under test
    git(repo, "add", "tools/device_slim.sh")
    git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "--allow-empty", "-m", "t")
    packings = [p for p in git(repo, "ls-files").split("\n") if p.endswith("packing.npz")]
    assert packings, "the checkout has committed packings"
    before = travelling(repo)

    def stays(p):       # what `on` keeps at home: packings, checkpoints, a ladder's committed final state
        return p.endswith(("packing.npz", "/final.h5")) or "/checkpoints/" in p
    assert [p for p in before if p.endswith("/final.h5")], "the checkout has a committed final state"

    on = slim(repo, "on")
    assert on.returncode == 0, on.stderr
    now = travelling(repo)
    assert not [p for p in now if stays(p)]
    assert all((repo / p).exists() for p in packings)                  # on disk still
    assert before - now == {p for p in before if stays(p)}
    assert slim(repo, "on").returncode == 1                           # not twice

    off = slim(repo, "off")
    assert off.returncode == 0, off.stderr
    assert git(repo, "status", "--porcelain") == ""
    assert travelling(repo) == before
    assert slim(repo, "off").returncode == 0                          # off twice is harmless
