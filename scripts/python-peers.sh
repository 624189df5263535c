#!/usr/bin/env bash
# Creates the Python venv of the interop peers (target/pyenv, not in git) and
# installs tests/python/requirements.txt into it. Idempotent: reinstalls only
# when the requirements change. Prints the venv's python on its last line.
#
#   scripts/python-peers.sh            # set up, print the interpreter
#   PY=$(scripts/python-peers.sh | tail -n1)
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${ATMO_PYENV:-target/pyenv}
req=tests/python/requirements.txt
stamp="$venv/.requirements.sha256"
want=$(sha256sum "$req" | cut -d' ' -f1)
if [[ ! -x "$venv/bin/python" ]]; then
    python3 -m venv "$venv" >&2
fi
if [[ ! -f "$stamp" || "$(cat "$stamp")" != "$want" ]]; then
    "$venv/bin/python" -m pip install --disable-pip-version-check -q -r "$req" >&2
    echo "$want" >"$stamp"
fi
echo "$(cd "$venv" && pwd)/bin/python"
