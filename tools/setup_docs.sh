#!/usr/bin/env bash
# Idempotent: .venv-docs, a virtual environment with Sphinx and MyST (the markdown of docs/) for the
# documentation site and its API reference (`make docs`, docs/conf.py). mpdem itself is not installed
# there: Sphinx's autodoc reads src/mpdem (its API modules import nothing heavy at import time).
# Pinned; some 30 MB, 10-20 s from PyPI. A stamp records a finished set-up.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
python=${PYTHON:-python3}
venv=${MPDEM_DOCS_VENV:-$here/.venv-docs}
want="sphinx==9.0.4 myst-parser==5.2.0"
stamp=$venv/.mpdem-docs-stamp
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    exit 0
fi
echo "setup-docs: making $venv ($want)"
rm -rf "$venv"
"$python" -m venv "$venv"
# shellcheck disable=SC2086
"$venv/bin/python" -m pip install -q --disable-pip-version-check $want
echo "$want" > "$stamp"
