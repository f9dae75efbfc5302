# soakcal service image: `soakcal serve` on 0.0.0.0:8000. The database comes from
# SOAKCAL_DATABASE_URL (docker-compose.yml sets PostgreSQL); without it, SQLite in /data.
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    SOAKCAL_DATA_DIR=/data

WORKDIR /app
# Dependencies first (cached layer), then the code.
COPY pyproject.toml README.md ./
COPY service ./service
COPY calibration ./calibration
COPY drivers ./drivers
COPY simulators ./simulators
RUN pip install . \
    && useradd --system --home-dir /data --create-home soakcal

USER soakcal
WORKDIR /data
EXPOSE 8000
HEALTHCHECK --interval=10s --timeout=3s --start-period=20s --retries=3 \
    CMD python -c "import urllib.request,sys; sys.exit(urllib.request.urlopen('http://127.0.0.1:8000/api/v1/health', timeout=2).status != 200)"
CMD ["soakcal", "serve", "--host", "0.0.0.0", "--port", "8000"]
