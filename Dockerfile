# One image for every hgrender service (api, worker, scheduler): docker-compose.yml picks the command.
FROM python:3.11-slim-bookworm

# libLLVM 19 for Dr.Jit's LLVM backend (bookworm ships 14/15, which crash): from apt.llvm.org.
ARG LLVM_VERSION=19
RUN apt-get update \
 && apt-get install -y --no-install-recommends ca-certificates curl gnupg \
 && curl -fsSL https://apt.llvm.org/llvm-snapshot.gpg.key | gpg --dearmor -o /usr/share/keyrings/llvm.gpg \
 && echo "deb [signed-by=/usr/share/keyrings/llvm.gpg] http://apt.llvm.org/bookworm/ llvm-toolchain-bookworm-${LLVM_VERSION} main" \
      > /etc/apt/sources.list.d/llvm.list \
 && apt-get update \
 && apt-get install -y --no-install-recommends libllvm${LLVM_VERSION} \
 && apt-get purge -y curl gnupg && apt-get autoremove -y \
 && rm -rf /var/lib/apt/lists/*

# PYTHONPATH=/app: the code runs from /app (not from the installed copy in site-packages) so that the API
# finds the viewer's static files in /app/web beside its package (service/api/routes/web.py).
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PYTHONPATH=/app \
    HGRENDER_DATA_DIR=/data

WORKDIR /app
# Dependencies first (cached layer): versions are pinned by pyproject.toml (mitsuba==3.9.1, drjit==1.5.0).
COPY pyproject.toml README.md ./
COPY hgcore ./hgcore
COPY hgrender ./hgrender
COPY service ./service
COPY worker ./worker
COPY schemas ./schemas
COPY web ./web
RUN pip install .

RUN useradd --create-home --uid 10001 hgrender \
 && mkdir -p /data && chown hgrender:hgrender /data
USER hgrender
VOLUME ["/data"]
EXPOSE 8000

HEALTHCHECK --interval=15s --timeout=5s --start-period=20s --retries=3 \
  CMD python -c "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=4).status == 200 else 1)"

CMD ["hgrender", "serve", "--host", "0.0.0.0", "--port", "8000", "--data-dir", "/data"]
