# One image for every service; the command chooses which: `stb router`, `stb monitor`, ...
#
#   docker compose build                                    # the official Python base
#   docker build --build-arg BASE=stb-base:bookworm .       # any Debian with python3.11 + venv
#
# BASE is the official image in a lab with a registry; deploy/docker/make-base builds an
# equivalent offline from Debian's archive. Where outbound HTTPS is intercepted, put the CA
# bundle that verifies it at deploy/docker/build-ca/ca-certificates.crt (git- and image-free:
# only the build stage sees it). docs/deployment.md §7.
ARG BASE=python:3.11-slim

FROM ${BASE} AS dependencies
# A C/C++ compiler (and Python's headers where the base lacks them), in the build stages only:
# numba links the marker detector's loop with it into a module that needs neither numba nor
# LLVM at run time (common/markers_aot.py). Without Debian's archive the image still builds,
# and the detector uses numba's JIT (about 120 MB more in each service that detects).
RUN command -v c++ >/dev/null || { apt-get update -qq && apt-get install -y -qq \
        --no-install-recommends g++ $(python3 -c "import sysconfig, os; \
print('' if os.path.isfile(sysconfig.get_paths()['include'] + '/Python.h') else 'python3-dev')") \
        >/dev/null && rm -rf /var/lib/apt/lists/*; } \
    || echo "no C++ compiler: the marker detector will use numba's JIT"
COPY deploy/docker/build-ca/ /tmp/build-ca/
# The dependencies alone (pyproject.toml's list), in a layer of their own: a change to the code
# rebuilds only what follows (seconds), not the installation of numpy, OpenCV, Zenoh... (a minute).
COPY pyproject.toml /src/
RUN if [ -f /tmp/build-ca/ca-certificates.crt ]; then \
        export PIP_CERT=/tmp/build-ca/ca-certificates.crt; fi \
 && python3 -c "import tomllib; print('\n'.join(tomllib.load(open('/src/pyproject.toml', \
'rb'))['project']['dependencies']))" > /tmp/requirements.txt \
 && python3 -m venv /opt/stb \
 && /opt/stb/bin/pip install --no-cache-dir --disable-pip-version-check -r /tmp/requirements.txt

FROM dependencies AS build
# The project itself, beside the dependencies (on PYTHONPATH, its `stb` in /opt/stb-app/bin).
COPY pyproject.toml README.md /src/
COPY common /src/common
COPY services /src/services
RUN if [ -f /tmp/build-ca/ca-certificates.crt ]; then \
        export PIP_CERT=/tmp/build-ca/ca-certificates.crt; fi \
 && /opt/stb/bin/pip install --no-cache-dir --disable-pip-version-check --no-deps \
        --target /opt/stb-app /src \
 && (cd / && PYTHONPATH=/opt/stb-app /opt/stb/bin/python -m common.markers_aot)

FROM ${BASE}
COPY --from=dependencies /opt/stb /opt/stb
COPY --from=build /opt/stb-app /opt/stb-app
ENV PATH=/opt/stb-app/bin:/opt/stb/bin:$PATH PYTHONPATH=/opt/stb-app PYTHONUNBUFFERED=1 \
    NUMBA_CACHE_DIR=/app/numba-cache MPLCONFIGDIR=/tmp/matplotlib
WORKDIR /app
# The marker detector's loop was built ahead in the build stage; where it could not be, the
# JIT's compile is cached here (numba's cache is keyed by the installed source file), so no
# service compiles at start. The folders that compose mounts
# volumes on (docker-compose.yml) exist here, owned by stb: a new volume takes their owner.
RUN (cd / && python3 -c "from common.markers import warm_up; warm_up()") \
 && useradd --system --uid 10001 --home-dir /app stb \
 && mkdir -p /app/run/sim /data/calib /app/numba-cache \
 && chown -R stb /app/run /data/calib /app/numba-cache
USER stb
# A lab file, if any, is named by STB_LAB (see docker-compose.yml).
ENTRYPOINT ["stb"]
