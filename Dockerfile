# fusiond as a container service: `fusiond run` on /etc/fusiond/config.toml.
#
#   docker build -t fusiond .
#   docker run --rm --network host -v $PWD/robot.toml:/etc/fusiond/config.toml:ro fusiond
#
# The default config (deploy/docker.toml) listens on tcp/0.0.0.0:7447; the
# HEALTHCHECK dials the config's listen endpoint on loopback and queries the
# health key: healthy while the status is ok or degraded, unhealthy when failed
# (no sensor alive, no odometry, filter non-finite), still starting once the
# start period is over (no odometry sample yet: nothing published) or not
# answering. A replacement config
# must keep a listen endpoint (or change the HEALTHCHECK to pass --connect).
# CI checks these install steps without Docker (tests/e2e/test_deploy.py).

FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

RUN useradd --system --uid 10001 --user-group --no-create-home --shell /usr/sbin/nologin fusiond

WORKDIR /opt/fusiond
COPY pyproject.toml setup.py README.md ./
COPY fusiond ./fusiond
# gcc builds the estimator's compiled kernels (fusiond/estimator/_kernels.c) and leaves with the
# build; without them the filter runs its numpy path, the same estimates at a higher CPU cost.
RUN apt-get update && apt-get install -y --no-install-recommends gcc libc6-dev \
    && pip install --no-cache-dir . && fusiond --help > /dev/null \
    && python -c "from fusiond.estimator import kernels; assert kernels.available()" \
    && apt-get purge -y --auto-remove gcc libc6-dev && rm -rf /var/lib/apt/lists/*
COPY deploy/docker.toml /etc/fusiond/config.toml

USER fusiond
EXPOSE 7447/tcp

HEALTHCHECK --interval=10s --timeout=8s --start-period=20s --retries=3 \
    CMD ["fusiond", "health", "--config", "/etc/fusiond/config.toml", "--timeout", "3"]

STOPSIGNAL SIGTERM
CMD ["fusiond", "run", "--config", "/etc/fusiond/config.toml"]
