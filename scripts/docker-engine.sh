#!/usr/bin/env bash
# Make sure a Docker engine and a compose implementation are here and running (as root, Debian).
# Installs Debian's docker.io + docker-compose (+ debootstrap for scripts/docker-base.sh) with
# apt-get when missing, and starts dockerd by hand (overlay2, cgroupfs) when no daemon answers:
# containers and CI machines have no systemd. Exits non-zero, saying why, when it cannot.
set -euo pipefail

LOG=${SPACEMAP_DOCKERD_LOG:-/var/log/spacemap-dockerd.log}
DEADLINE_S=${SPACEMAP_DOCKERD_WAIT_S:-60}

need=()
command -v dockerd >/dev/null 2>&1 || need+=(docker.io)
command -v docker >/dev/null 2>&1 || need+=(docker.io)
command -v docker-compose >/dev/null 2>&1 || docker compose version >/dev/null 2>&1 \
  || need+=(docker-compose)
command -v debootstrap >/dev/null 2>&1 || need+=(debootstrap)
if [ ${#need[@]} -gt 0 ]; then
  echo "docker-engine: installing Debian packages: ${need[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends $(printf '%s\n' "${need[@]}" | sort -u)
fi

if docker info >/dev/null 2>&1; then
  echo "docker-engine: daemon already running"
  exit 0
fi
if [ "$(id -u)" != 0 ]; then
  echo "docker-engine: no daemon answers and starting one needs root" >&2
  exit 1
fi
echo "docker-engine: starting dockerd (log: $LOG)"
# setsid: the daemon outlives this script and the test that ran it.
setsid dockerd --storage-driver=overlay2 --exec-opt native.cgroupdriver=cgroupfs \
  >>"$LOG" 2>&1 < /dev/null &
end=$((SECONDS + DEADLINE_S))
until docker info >/dev/null 2>&1; do
  if [ $SECONDS -ge $end ] || ! kill -0 $! 2>/dev/null; then
    echo "docker-engine: dockerd did not come up in ${DEADLINE_S}s; last log lines:" >&2
    tail -n 20 "$LOG" >&2
    exit 1
  fi
  sleep 0.5
done
echo "docker-engine: dockerd is up"
