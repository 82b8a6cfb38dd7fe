#!/usr/bin/env bash
# Build the spacemap image with no container registry and no network inside the build:
# a local Debian base (scripts/docker-base.sh) and a wheelhouse made on the host
# (scripts/docker-wheels.sh), made side by side, then a BuildKit `docker build --network none`.
#
#   bash scripts/docker-build.sh           # -> spacemap:latest (what docker-compose.yml runs)
#   IMAGE=NAME:TAG bash scripts/docker-build.sh
# Both inputs are cached (SPACEMAP_BUILD_CACHE, default /var/cache/spacemap), and Docker's
# layer cache makes an unchanged rebuild a few seconds.
set -euo pipefail
cd "$(dirname "$0")/.."

IMAGE=${IMAGE:-spacemap:latest}
log() { echo "docker-build: $*" >&2; }

start=$SECONDS
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
bash scripts/docker-base.sh > "$tmp/base" &
base_pid=$!
bash scripts/docker-wheels.sh &
wheels_pid=$!
wait "$wheels_pid" || { log "wheelhouse failed"; kill "$base_pid" 2>/dev/null; exit 1; }
wait "$base_pid" || { log "base image failed"; exit 1; }
BASE=$(tail -n1 "$tmp/base")
log "inputs ready in $((SECONDS - start)) s: base $BASE, wheelhouse/"

# BuildKit (the Dockerfile bind-mounts the wheelhouse): the CLI's buildx, else Debian's
# docker.io CLI, whose `docker build` has BuildKit built in.
DOCKER=docker
if ! docker buildx version >/dev/null 2>&1 && [ -x /usr/bin/docker ]; then DOCKER=/usr/bin/docker; fi
DOCKER_BUILDKIT=1 "$DOCKER" build --progress plain --network none --build-arg BASE="$BASE" \
  --build-arg OFFLINE=1 -t "$IMAGE" . >&2
log "built $IMAGE in $((SECONDS - start)) s ($(docker image inspect -f '{{.Size}}' "$IMAGE" \
  | awk '{printf "%.0f MB", $1 / 1e6}'))"
