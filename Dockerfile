# One image for every service; the command chooses which: `stb router`, `stb monitor`, ...
FROM python:3.11-slim
WORKDIR /app
COPY pyproject.toml README.md ./
COPY common ./common
COPY services ./services
RUN pip install --no-cache-dir . \
 && useradd --system --uid 10001 --home-dir /app stb \
 && mkdir -p /app/run && chown stb /app/run
USER stb
# A lab file, if any, is named by STB_LAB (see docker-compose.yml).
ENV PYTHONUNBUFFERED=1 NUMBA_CACHE_DIR=/tmp/numba-cache
ENTRYPOINT ["stb"]
