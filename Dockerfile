# One image for every service; the command chooses which: `stb router`, `stb monitor`, ...
FROM python:3.11-slim
WORKDIR /app
COPY pyproject.toml README.md ./
COPY common ./common
COPY services ./services
# The marker detector's compiled loop is built into the image (from the installed package, not
# /app's copy: numba's cache is keyed by the source file), so no service compiles at start.
ENV PYTHONUNBUFFERED=1 NUMBA_CACHE_DIR=/app/numba-cache
RUN pip install --no-cache-dir . \
 && (cd / && python -c "from common.markers import warm_up; warm_up()") \
 && useradd --system --uid 10001 --home-dir /app stb \
 && mkdir -p /app/run && chown -R stb /app/run /app/numba-cache
USER stb
# A lab file, if any, is named by STB_LAB (see docker-compose.yml).
ENTRYPOINT ["stb"]
