# The tofpose server with simulated devices. Build: docker build -t tofpose .
# Run: docker run -p 8000:8000 -v tofpose-data:/data tofpose
# Bound to 0.0.0.0 inside the container, so reads need the token too (printed at start,
# stored in /data/api_token). The 3-D scene (viser, port 8080) has no token check, so it
# runs only with open reads: docker run -p 8000:8000 -p 8080:8080
#   -e TOFPOSE_OPEN_READS=true -v tofpose-data:/data tofpose
# The live Foxglove stream (docs/interop.md) likewise, on a port of its choosing:
#   ... -p 8765:8765 -e TOFPOSE_FOXGLOVE_PORT=8765 -e TOFPOSE_OPEN_READS=true ...
# Stage 1: the dashboard (frontend/), built with Node from its lock file.
FROM node:20-slim AS dashboard
WORKDIR /frontend
COPY frontend/package.json frontend/package-lock.json ./
RUN npm ci --no-audit --no-fund
COPY frontend/ ./
RUN npm run build

# Stage 2: the server, serving the built dashboard at /.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    TOFPOSE_DATA_DIR=/data \
    TOFPOSE_HOST=0.0.0.0 \
    TOFPOSE_PORT=8000

WORKDIR /app
COPY pyproject.toml setup.py MANIFEST.in README.md alembic.ini ./
COPY tofpose ./tofpose
COPY backend ./backend
COPY migrations ./migrations
# The dashboard built in stage 1, where setup.py's build step takes it from: this image
# has no Node.js, and the wheel ships the dashboard as backend/dashboard.
COPY --from=dashboard /frontend/dist ./frontend/dist
# A regular install, as from a release wheel: it carries the Alembic revisions as
# backend/migrations, which the server applies at every start, and the dashboard
# (tests/test_packaging.py checks both). The extras bring the real-device drivers
# (ESPROS's client, PyVISA); docs/devices.md. `tofpose warm-up` compiles the pipeline's
# numba kernels into the image's cache, so that a container starts without the ~1 min
# first compile.
RUN pip install '.[espros,scpi]' && tofpose warm-up && mkdir -p /data

EXPOSE 8000 8080
VOLUME ["/data"]
CMD ["tofpose", "serve"]
