# One image for every LAMPS service (sim, controller, perception, recorder);
# docker-compose.yml picks the command. CPU only, no display.
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg

# libgl1/libglib2.0-0: PyBullet's TinyRenderer and OpenCV's runtime needs
RUN apt-get update \
    && apt-get install -y --no-install-recommends libgl1 libglib2.0-0 \
    && rm -rf /var/lib/apt/lists/*

RUN useradd --create-home --uid 1000 lamps
WORKDIR /opt/lamps

# dependencies first (cached while only the code changes)
COPY pyproject.toml README.md ./
RUN mkdir -p controller sim perception interfaces launch \
    && pip install . && pip uninstall -y lamps

COPY lampskit ./lampskit
COPY robot ./robot
COPY controller ./controller
COPY sim ./sim
COPY perception ./perception
COPY interfaces ./interfaces
COPY launch ./launch
COPY config ./config
RUN pip install --no-deps . && lamps --help > /dev/null

# the compiled control law (numba) is cached where the service user can write, and filled at build time
ENV NUMBA_CACHE_DIR=/var/cache/lamps-numba
RUN mkdir -p /runs /skills /var/cache/lamps-numba && chown lamps:lamps /runs /var/cache/lamps-numba
USER lamps
RUN python -c "from controller.core import ControllerCore; from controller.params import ControllerParams; \
from lampskit.learn.learn import bundled_skill; ControllerCore(ControllerParams.from_table({}), bundled_skill())"
# Zenoh endpoints of the services (each listens on its own)
EXPOSE 7447 7448 7449
CMD ["lamps", "--help"]
