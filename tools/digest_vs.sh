#!/bin/bash
# Same digest as an earlier commit? Runs a small pile with this tree and with REV.
#
#   tools/digest_vs.sh REV [STEPS] [section.key=value ...]
#
# e.g. tools/digest_vs.sh cb7892e 20000 contact.model=hertz
# For kernel work that must change memory, not arithmetic: a 600-sphere pile
# in a 7 d box, one rank, from the same config; prints "same" or "DIFFERENT"
# with both digests (exit 0 or 1). REV is checked out in a temporary worktree.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
rev=${1:?usage: tools/digest_vs.sh REV [STEPS] [section.key=value ...]}; shift
steps=${1:-20000}; [ $# -gt 0 ] && shift
py=$here/.venv/bin/python
[ -x "$py" ] || { echo "run make setup first ($py missing)" >&2; exit 2; }
tmp=$(mktemp -d /tmp/digest_vs.XXXXXX)
trap 'git -C "$here" worktree remove --force "$tmp/old" >/dev/null 2>&1 || true; rm -rf "$tmp"' EXIT
git -C "$here" worktree add -q --detach "$tmp/old" "$rev"
args=(--set "run.max_steps=$steps" --set pour.N=600 --set box.L_x=7.0 --set box.L_y=7.0 --quiet)
for s in "$@"; do args+=(--set "$s"); done
# exit 3: stopped at run.max_steps, which is what is wanted here
run() { PYTHONPATH=$1 "$py" -m mpdem run "${args[@]}" --out "$2" >/dev/null || [ $? -eq 3 ]; }
run "$tmp/old/src" "$tmp/run_old"
run "$here/src" "$tmp/run_new"
a=$(PYTHONPATH=$here/src "$py" -m mpdem info "$tmp/run_old/final.h5" --digest | tail -1)
b=$(PYTHONPATH=$here/src "$py" -m mpdem info "$tmp/run_new/final.h5" --digest | tail -1)
if [ "$a" = "$b" ]; then echo "same: $a"; else echo "DIFFERENT: $rev $a, this tree $b"; exit 1; fi
