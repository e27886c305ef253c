# Sourced by ./lamps and ./run-tests: make sure .venv holds this checkout's
# package with the extras asked for, reinstalling only when pyproject.toml
# changed or an extra is missing. An install keeps the extras it already
# had, so alternating ./lamps and ./run-tests installs nothing. Needs only
# python3 (>= 3.11) with venv and pip.
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
want="$(sha256sum < "$root/pyproject.toml" | cut -c1-16)"
# the stamp: "<pyproject hash> <extras installed, comma-separated>"
read -r have_hash have_extras < "$stamp" 2>/dev/null || { have_hash=""; have_extras=""; }
need="$have_extras"
if [ "$have_hash" != "$want" ]; then need=""; fi
missing=""
for e in ${extras//,/ }; do
    case ",$need," in *",$e,"*) ;; *) missing="$missing,$e" ;; esac
done
if [ ! -x "$venv/bin/python" ] || [ "$have_hash" != "$want" ] || [ -n "$missing" ]; then
    all="$(echo "${have_extras},${extras}" | tr ',' '\n' | sed '/^$/d' | sort -u | paste -sd, -)"
    echo "lamps: installing into $venv (first run, pyproject.toml changed or extras [${extras}] missing) ..." >&2
    [ -x "$venv/bin/python" ] || "$py" -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --upgrade pip >&2
    spec="$root"
    [ -n "$all" ] && spec="$root[$all]"
    "$venv/bin/python" -m pip install --quiet -e "$spec" >&2
    echo "$want $all" > "$stamp"
fi
