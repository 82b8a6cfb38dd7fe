#!/usr/bin/env bash
# Build the wheelhouse the Dockerfile installs from with `pip install --no-index`: wheels of
# spacemap's dependencies, of setuptools and wheel (building the project needs them) and of pip
# (the build runs pip from its wheel), made on this host by `pip wheel`, so the image build
# needs no network. The host's pip settings (index, mirrors, find-links) apply; a container's
# pip never sees them.
#
#   bash scripts/docker-wheels.sh          # -> wheelhouse/*.whl
#   PYTHON=python3.11                      # a CPython 3.11 (the image's Python); default .venv's
#   SPACEMAP_BUILD_CACHE=DIR               # keeps a copy keyed on the dependency lists
#                                          # (default /var/cache/spacemap)
set -euo pipefail
cd "$(dirname "$0")/.."
log() { echo "docker-wheels: $*" >&2; }

PY=${PYTHON:-.venv/bin/python}
[ -x "$PY" ] || command -v "$PY" >/dev/null 2>&1 || PY=python3.11
CACHE=${SPACEMAP_BUILD_CACHE:-/var/cache/spacemap}
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
  || { log "$PY is not Python 3.11, the image's Python"; exit 1; }

# The key: the dependency lists and this script (not the rest of pyproject.toml).
KEY=$({ "$PY" -c 'import tomllib; d = tomllib.load(open("pyproject.toml", "rb"))
print(d["project"]["dependencies"], d["build-system"]["requires"])'; cat "$0"; } \
  | sha256sum | cut -c1-12)
KEPT=$CACHE/wheels-$KEY
OUT=wheelhouse


mkdir -p "$CACHE" "$OUT"
exec 9>"$CACHE/wheels.lock"
flock 9   # one filler at a time (two checkouts building at once share the cache)
if [ ! -f "$KEPT/.complete" ]; then
  rm -rf "$KEPT.part"
  log "pip wheel of the project and its dependencies into $KEPT"
  "$PY" -m pip wheel -q -w "$KEPT.part" . "setuptools>=68" wheel pip >&2
  rm -f "$KEPT.part"/spacemap-*.whl   # the image builds the project from its copied source
  touch "$KEPT.part/.complete"
  rm -rf "$KEPT"
  mv "$KEPT.part" "$KEPT"
else
  log "cached wheels $KEPT"
fi
# Replace the wheelhouse's wheels with the kept set (hard links when on one file system),
# unless it holds that set already: untouched files keep Docker's context transfer short.
if [ "$(cd "$KEPT" && ls -- *.whl)" != "$(cd "$OUT" && ls -- *.whl 2>/dev/null)" ]; then
  find "$OUT" -maxdepth 1 -name '*.whl' -delete
  cp -l "$KEPT"/*.whl "$OUT"/ 2>/dev/null || cp "$KEPT"/*.whl "$OUT"/
fi
log "$(find "$OUT" -name '*.whl' | wc -l) wheels in $OUT ($(du -sh "$OUT" | cut -f1))"
