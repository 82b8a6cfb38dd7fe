# spacemap: one image for every service (router, sim, edge, agent, record, run).
# Needs BuildKit (`docker compose build`, `docker buildx build`, `DOCKER_BUILDKIT=1 docker
# build`): the wheelhouse and the source are bind-mounted into the install steps, never copied
# into a layer. No `# syntax=` line: the builder's own Dockerfile frontend, nothing to pull.
#
# Online (a registry and PyPI reachable):  docker compose build
# Offline (no registry, no network in the build; README "Docker"):  bash scripts/docker-build.sh
#   (a debootstrapped Debian base + a wheelhouse made on the host; OFFLINE=1: pip --no-index)
#
# BASE: any Debian bookworm image with CPython 3.11 as `python3.11`. The default is the public
# slim image; scripts/docker-base.sh makes a local one that also holds the libraries below.
ARG BASE=python:3.11-slim-bookworm
FROM ${BASE}

# open3d needs libusb and libGL (and libgomp); MuJoCo's offscreen rendering on the CPU needs
# EGL/Mesa (or OSMesa). Installed only when the base lacks them (a local base has them all).
RUN set -eu; need=""; \
    for pkg in libusb-1.0-0 libgl1 libegl1 libgl1-mesa-dri libegl-mesa0 libosmesa6 libgomp1; do \
      dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" \
        || need="$need $pkg"; \
    done; \
    if [ -n "$need" ]; then \
      apt-get update && apt-get install -y --no-install-recommends $need \
      && rm -rf /var/lib/apt/lists/*; \
    fi

# pip runs from the wheelhouse's pip wheel (else the base's own pip) on the venv's behalf
# (`--python`), so the venv holds no pip. OFFLINE=1: wheelhouse only (pip --no-index).
ARG OFFLINE=0
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_ROOT_USER_ACTION=ignore

# The dependencies, a layer of their own: rebuilt only when pyproject.toml or the wheelhouse
# changes.
RUN --mount=type=bind,source=wheelhouse,target=/wheels \
    --mount=type=bind,source=pyproject.toml,target=/tmp/pyproject.toml \
    set -eu; if [ "$OFFLINE" = 1 ]; then idx="--no-index"; else idx=""; fi; \
    pip=$(ls /wheels/pip-*.whl 2>/dev/null | tail -n1); pip=${pip:+$pip/pip}; \
    python3.11 -m venv --without-pip /opt/venv; \
    python3.11 -c 'import tomllib; print("\n".join(tomllib.load(open("/tmp/pyproject.toml", \
      "rb"))["project"]["dependencies"]))' > /tmp/requirements.txt; \
    python3.11 ${pip:--m pip} --python /opt/venv/bin/python install $idx --find-links /wheels \
      -r /tmp/requirements.txt; \
    rm /tmp/requirements.txt

# The project itself (small): installed from its bind-mounted source; the build's scratch
# files (/src) go in the same step.
RUN --mount=type=bind,source=pyproject.toml,target=/src/pyproject.toml \
    --mount=type=bind,source=README.md,target=/src/README.md \
    --mount=type=bind,source=schemas,target=/src/schemas \
    --mount=type=bind,source=services,target=/src/services \
    --mount=type=bind,source=wheelhouse,target=/wheels \
    set -eu; if [ "$OFFLINE" = 1 ]; then idx="--no-index"; else idx=""; fi; \
    pip=$(ls /wheels/pip-*.whl 2>/dev/null | tail -n1); pip=${pip:+$pip/pip}; \
    cp -r /src /tmp/src; \
    python3.11 ${pip:--m pip} --python /opt/venv/bin/python install $idx --no-deps \
      --find-links /wheels /tmp/src; \
    rm -rf /tmp/src /root/.cache; \
    /opt/venv/bin/python -m services.common.grid_search

ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    OPENBLAS_NUM_THREADS=1 \
    MUJOCO_GL=egl \
    SPACEMAP_CACHE=/runs/.cache
# Run folders (and the ground-truth cache) go to the shared volume.
VOLUME ["/runs"]
WORKDIR /runs
EXPOSE 7447
ENTRYPOINT ["spacemap"]
CMD ["--help"]
