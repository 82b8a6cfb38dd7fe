#!/usr/bin/env bash
# Make a local Debian bookworm base image with Python 3.11 and the runtime libraries spacemap
# needs, without any container registry: debootstrap (minbase) from the Debian mirror, then
# `docker import`. Prints the image name on stdout's last line. Cached: the tag carries a hash of
# this script, so an unchanged script reuses the image (or the rootfs tarball in the cache dir).
#
#   bash scripts/docker-base.sh            # -> spacemap-base:bookworm-<hash>
#   SPACEMAP_BUILD_CACHE=DIR  where the rootfs tarball is kept (default /var/cache/spacemap)
#   DEBIAN_MIRROR=URL         default: the host's apt mirror, else http://deb.debian.org/debian
set -euo pipefail
cd "$(dirname "$0")/.."

# python3.11 (its venv module: `venv --without-pip`; the build runs pip from the wheelhouse);
# the rest are what open3d (libusb, libGL, libgomp) and MuJoCo's offscreen EGL/OSMesa
# rendering load at run time.
PACKAGES=python3.11,libusb-1.0-0,libgl1,libegl1,libgl1-mesa-dri,libegl-mesa0,libosmesa6,libgomp1

CACHE=${SPACEMAP_BUILD_CACHE:-/var/cache/spacemap}
KEY=$(sha256sum "$0" | cut -c1-12)
IMAGE=spacemap-base:bookworm-$KEY
TARBALL=$CACHE/base-bookworm-$KEY.tar

log() { echo "docker-base: $*" >&2; }

mkdir -p "$CACHE"
exec 9>"$CACHE/base.lock"
flock 9   # one builder at a time (two checkouts building at once share the cache)
if docker image inspect "$IMAGE" >/dev/null 2>&1; then
  log "cached image $IMAGE"
  echo "$IMAGE"
  exit 0
fi
if [ ! -s "$TARBALL" ]; then
  if [ -z "${DEBIAN_MIRROR:-}" ]; then
    DEBIAN_MIRROR=$(grep -h -o -E 'https?://[^ ]+/debian/?$' /etc/apt/sources.list.d/*.sources \
      /etc/apt/sources.list 2>/dev/null | head -n1 || true)
    DEBIAN_MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
  fi
  command -v debootstrap >/dev/null 2>&1 || {
    log "installing debootstrap"
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends debootstrap >&2
  }
  ROOTFS=$(mktemp -d "$CACHE/rootfs.XXXXXX")
  trap 'rm -rf "$ROOTFS"' EXIT
  log "debootstrap bookworm from $DEBIAN_MIRROR into $ROOTFS"
  debootstrap --variant=minbase --include="$PACKAGES" bookworm "$ROOTFS" "$DEBIAN_MIRROR" >&2
  # What a slim base image leaves out: package caches and lists, docs, man pages, locales.
  rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/cache/apt/*.bin \
    "$ROOTFS"/var/lib/apt/lists/* "$ROOTFS"/usr/share/doc/* "$ROOTFS"/usr/share/man/* \
    "$ROOTFS"/usr/share/info/* "$ROOTFS"/var/log/*.log "$ROOTFS"/var/cache/debconf/*-old
  find "$ROOTFS"/usr/share/locale -mindepth 1 -maxdepth 1 ! -name 'locale.alias' \
    -exec rm -rf {} + 2>/dev/null || true
  echo "deb $DEBIAN_MIRROR bookworm main" > "$ROOTFS"/etc/apt/sources.list
  tar -C "$ROOTFS" -cf "$TARBALL.part" .
  mv "$TARBALL.part" "$TARBALL"
fi
log "docker import $TARBALL as $IMAGE"
docker import --change 'ENV LANG=C.UTF-8' --change 'CMD ["/bin/bash"]' "$TARBALL" "$IMAGE" >&2
echo "$IMAGE"
