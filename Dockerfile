# One image for every LAMPS service (sim, controller, perception, recorder);
# docker-compose.yml picks the command. CPU only, no display.
#
# BASE_IMAGE: any Debian-like image with Python 3.11 and its venv module. The
# public python:3.11-slim-bookworm by default; where no registry is reachable,
# scripts/docker-base.sh makes lamps-base:bookworm with debootstrap, and
#   docker compose build --build-arg BASE_IMAGE=lamps-base:bookworm
# (or LAMPS_BASE_IMAGE=lamps-base:bookworm docker compose up --build) uses it.
ARG BASE_IMAGE=python:3.11-slim-bookworm
FROM ${BASE_IMAGE}

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg \
    VIRTUAL_ENV=/opt/venv \
    PATH=/opt/venv/bin:$PATH

# One system package: libgomp1, the OpenMP runtime Pinocchio's wheel links to.
# The rest are self-contained wheels (PyBullet renders with its TinyRenderer,
# OpenCV is the headless build): no GL, no X, no compilers.
RUN apt-get update \
    && apt-get install -y --no-install-recommends libgomp1 \
    && rm -rf /var/lib/apt/lists/* /var/cache/apt/archives/*.deb \
    && python3 -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
    && python3 -m venv /opt/venv \
    && useradd --create-home --uid 1000 lamps
WORKDIR /opt/lamps

# dependencies first, exactly as locked (scripts/lock.sh), cached while only the code changes
COPY requirements.lock ./
RUN pip install --require-hashes --no-deps -r requirements.lock && pip check

COPY pyproject.toml README.md docker-compose.yml ./
COPY lampskit ./lampskit
COPY robot ./robot
COPY controller ./controller
COPY sim ./sim
COPY perception ./perception
COPY interfaces ./interfaces
COPY runtime ./runtime
COPY arm ./arm
COPY launch ./launch
COPY config ./config
RUN pip install --no-deps --no-build-isolation . && rm -rf build *.egg-info && lamps --version

# the compiled control law (numba) is cached where any service user can write, and filled at build time
ENV NUMBA_CACHE_DIR=/var/cache/lamps-numba
RUN mkdir -p /runs /skills /secrets /var/cache/lamps-numba \
    && chown lamps:lamps /runs /skills /secrets
USER lamps
RUN python -c "from controller.core import ControllerCore; from controller.params import ControllerParams; \
from lampskit.learn.learn import bundled_skill; ControllerCore(ControllerParams.from_table({}), bundled_skill())"
USER root
RUN chmod -R a+rwX /var/cache/lamps-numba
USER lamps
# Zenoh endpoints of the services (each listens on its own)
EXPOSE 7447 7448 7449
CMD ["lamps", "--help"]
