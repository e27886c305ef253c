#!/usr/bin/env bash
# Makes the base image the Dockerfile builds on where no container registry
# is reachable: Debian bookworm (minbase) with Python 3.11, venv and the CA
# certificates, made with debootstrap from Debian's packages and imported
# into the local engine. Does nothing when the image exists.
#
#   scripts/docker-base.sh [TAG]          # default lamps-base:bookworm
#   docker compose build --build-arg BASE_IMAGE=lamps-base:bookworm
#   LAMPS_BASE_IMAGE=lamps-base:bookworm docker compose up --build
#
# LAMPS_CA_BUNDLE (default: this host's /etc/ssl/certs/ca-certificates.crt)
# becomes the image's CA bundle, so pip in the build trusts what this host
# trusts (a TLS-inspecting proxy's CA included); DEBIAN_MIRROR picks the
# mirror. Needs root (debootstrap) and a running Docker engine.
set -euo pipefail
tag="${1:-lamps-base:bookworm}"
mirror="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
ca="${LAMPS_CA_BUNDLE:-/etc/ssl/certs/ca-certificates.crt}"

if docker image inspect "$tag" >/dev/null 2>&1; then
    echo "docker-base: $tag exists"
    exit 0
fi
if ! command -v debootstrap >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "docker-base: installing Debian's debootstrap ..." >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q debootstrap >/dev/null
    else
        echo "docker-base: debootstrap is missing (apt-get install debootstrap, as root)" >&2
        exit 1
    fi
fi
if [ ! -r "$ca" ]; then
    echo "docker-base: CA bundle $ca is not readable (set LAMPS_CA_BUNDLE)" >&2
    exit 1
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
echo "docker-base: debootstrap bookworm into $work (from $mirror) ..." >&2
debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
    bookworm "$work/rootfs" "$mirror" > "$work/debootstrap.log" 2>&1 || {
    tail -20 "$work/debootstrap.log" >&2
    echo "docker-base: debootstrap failed (log above)" >&2
    exit 1
}
cp "$ca" "$work/rootfs/etc/ssl/certs/ca-certificates.crt"
# no package caches, lists or logs in the image
rm -rf "$work/rootfs/var/cache/apt/archives/"*.deb "$work/rootfs/var/lib/apt/lists/"* \
    "$work/rootfs/var/log/"*.log "$work/rootfs/debootstrap"
tar -C "$work/rootfs" --numeric-owner -c . | docker import \
    -c 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    -c 'ENV LANG=C.UTF-8' \
    -c 'CMD ["/bin/bash"]' \
    -m "Debian bookworm minbase + python3, python3-venv, ca-certificates (scripts/docker-base.sh)" \
    - "$tag" >/dev/null
echo "docker-base: made $tag ($(docker image inspect -f '{{.Size}}' "$tag" | awk '{printf "%.0f MB", $1/1e6}'))"
