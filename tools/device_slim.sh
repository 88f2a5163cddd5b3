#!/usr/bin/env bash
# Keep the committed packings, checkpoints and final states of analysis/results from travelling to a lent
# GPU machine, for one device call, and put them back after. The device sends the working tree's tracked
# files and its untracked files that git does not ignore, at most 64 MiB in all; the result packings
# (packing.npz), the checkpoints of unfinished rows and the final states a ladder's rungs kept (final.h5,
# for a frictional rung above them) are most of the tracked bytes, and the GPU check
# (tools/gpu_check.sh) needs none of them (its reference runs are their config.toml and summary.json).
#   bash tools/device_slim.sh on       untrack them in the index only (the files stay on disk) and ignore
#                                      them (lines appended to the results' .gitignore files, whose own
#                                      "!packing.npz" would outrank .git/info/exclude): they do not travel
#   bash tools/device_slim.sh off      track them again and restore those .gitignore files: as before
#   bash tools/device_slim.sh status   what would travel now, in MiB, and whether the slim state is on
# Never commit while it is on: the commit would delete the packings. `off` is safe to run twice.
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
IGNORES=(analysis/results/paper/.gitignore analysis/results/dev/.gitignore)
LIST="$(git rev-parse --git-dir)/device_slim.list"
count() { tr -cd '\0' < "$LIST" | wc -c; }

travelling() {
    local b
    b=$( { git ls-files -z; git ls-files -z --others --exclude-standard; } | xargs -0 -r cat 2>/dev/null | wc -c)
    echo "$((b / 1048576)) MiB ($b bytes) would travel: tracked and untracked-not-ignored files"
}

case "${1:-status}" in
on)
    if [ -f "$LIST" ]; then echo "device_slim: already on ($(count) files untracked); 'off' first" >&2; exit 1; fi
    if ! git diff --quiet HEAD -- "${IGNORES[@]}"; then
        echo "device_slim: ${IGNORES[*]} have changes of their own; commit or drop them first" >&2; exit 1
    fi
    # a frictional ladder's rung may keep its final.h5 (the state its next rung starts from)
    git ls-files -z -- 'analysis/results/**/packing.npz' 'analysis/results/**/checkpoints/*' \
        'analysis/results/**/final.h5' > "$LIST"
    [ -s "$LIST" ] || { echo "device_slim: nothing to untrack"; rm -f "$LIST"; exit 0; }
    for f in "${IGNORES[@]}"; do
        # the last matching line of a .gitignore wins: these outrank its "!...packing.npz"
        printf '%s\n' "# device_slim.sh on (bash tools/device_slim.sh off restores this file)" \
            "**/packing.npz" "**/checkpoints/" "**/final.h5" >> "$f"
    done
    xargs -0 git rm -q --cached -- < "$LIST"
    echo "device_slim: on, $(count) files untracked and ignored (on disk still); do not commit until 'off'"
    travelling
    ;;
off)
    if [ -f "$LIST" ]; then
        xargs -0 git reset -q HEAD -- < "$LIST"
        rm -f "$LIST"
        git checkout -q HEAD -- "${IGNORES[@]}"
    fi
    echo "device_slim: off"
    travelling
    ;;
status)
    if [ -f "$LIST" ]; then echo "device_slim: on (do not commit)"; else echo "device_slim: off"; fi
    travelling
    ;;
*)
    echo "usage: bash tools/device_slim.sh on|off|status" >&2
    exit 2
    ;;
esac
