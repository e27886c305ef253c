#!/usr/bin/env bash
# Regenerates requirements.lock, the exact versions and hashes the image
# installs (Dockerfile), for CPython 3.11 on every platform pyproject.toml
# allows (x86_64 and aarch64 wheels alike): the runtime dependencies of
# pyproject.toml plus the build backend (setuptools, wheel) for installing
# the package itself without a network. Run after changing a dependency
# range; the tests check the lock still satisfies pyproject.toml.
# Uses uv (from PyPI, in a throw-away venv); reaches the package index.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
python3 -m venv "$tmp/venv"
"$tmp/venv/bin/pip" install --quiet "uv>=0.9,<1"
printf 'setuptools>=68,<81\nwheel>=0.42,<1\n' > "$tmp/build.in"
cd "$root"
"$tmp/venv/bin/uv" pip compile pyproject.toml "$tmp/build.in" --universal --python-version 3.11 \
    --generate-hashes --native-tls --index-url "${LAMPS_INDEX_URL:-https://pypi.org/simple}" \
    --no-header --quiet -o "$tmp/requirements.lock"
{
    echo "# The image's exact dependencies with hashes (CPython 3.11, every platform): scripts/lock.sh writes it"
    echo "# from pyproject.toml's ranges; the Dockerfile installs it with --require-hashes."
    grep -v "^    # via $tmp" "$tmp/requirements.lock" | sed "s#$tmp/build.in#build backend#"
} > "$tmp/out"
mv "$tmp/out" "$root/requirements.lock"
echo "lock: $(grep -c '^[a-z]' "$root/requirements.lock") packages in requirements.lock"
