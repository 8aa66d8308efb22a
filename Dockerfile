# One image for the API and the workers (see docker-compose.yml).
# Both run uploaded planners (the API their dry run, the workers their runs) in the sandbox:
# bubblewrap (0.8 or later: Debian 12's) for the namespaces, libseccomp for its seccomp filter,
# and the container's own cgroups, made writable at start by the entry point
# (worker/sandbox/container_init.py). Without them uploads are refused and runs of uploaded
# planners fail (docs/sandbox.md). tests/sandbox/test_container_image.py checks this image's
# isolation with the settings docker-compose.yml gives it.
FROM python:3.11-slim-bookworm
RUN apt-get update -qq \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      libusb-1.0-0 libgl1 libegl1 libgomp1 curl bubblewrap libseccomp2 \
 && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml README.md ./
COPY flybo flybo
COPY areas areas
COPY sim sim
COPY planners planners
COPY server server
COPY worker worker
COPY web web
COPY migrations migrations
RUN pip install --no-cache-dir -e '.[s3]'
ENV FLYBO_DATA_DIR=/data FLYBO_CACHE_DIR=/data/cache
VOLUME /data
EXPOSE 8000
ENTRYPOINT ["python", "-m", "worker.sandbox.container_init"]
CMD ["flybo", "serve", "--host", "0.0.0.0", "--port", "8000", "--workers", "0"]
