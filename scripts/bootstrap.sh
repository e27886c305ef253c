# Sourced by ./lamps and ./run-tests: make sure .venv holds this checkout's
# package with the extras asked for, reinstalling only when pyproject.toml
# changed. Needs only python3 (>= 3.11) with venv and pip.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${LAMPS_VENV:-$root/.venv}"
extras="${1:-}"
py="${PYTHON:-python3}"
if ! "$py" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)'; then
    echo "lamps: Python >= 3.11 is required ($("$py" --version 2>&1) found); set PYTHON=/path/to/python3.11" >&2
    exit 1
fi
stamp="$venv/.lamps-installed"
want="$( (cat "$root/pyproject.toml"; echo "extras=$extras") | sha256sum | cut -c1-16)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "lamps: installing into $venv (first run or pyproject.toml changed) ..." >&2
    [ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --upgrade pip >&2
    spec="$root"
    [ -n "$extras" ] && spec="$root[$extras]"
    "$venv/bin/python" -m pip install --quiet -e "$spec" >&2
    echo "$want" > "$stamp"
fi
