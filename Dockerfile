# spacemap: one image for every service (router, sim, edge, agent, run).
FROM python:3.11-slim-bookworm

# open3d needs libusb; MuJoCo's offscreen rendering on the CPU needs EGL/Mesa (or OSMesa).
RUN apt-get update \
 && apt-get install -y --no-install-recommends \
      libusb-1.0-0 libegl1 libgl1-mesa-dri libegl-mesa0 libosmesa6 libgomp1 \
 && rm -rf /var/lib/apt/lists/*

ENV PYTHONUNBUFFERED=1 \
    OPENBLAS_NUM_THREADS=1 \
    MUJOCO_GL=egl

WORKDIR /opt/spacemap
COPY pyproject.toml README.md ./
COPY schemas ./schemas
COPY services ./services
RUN pip install --no-cache-dir .

# Run outputs (run folders, ground-truth cache) go to the shared volume.
ENV SPACEMAP_CACHE=/runs/.cache
VOLUME ["/runs"]
EXPOSE 7447
ENTRYPOINT ["spacemap"]
CMD ["--help"]
