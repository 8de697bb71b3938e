# Prometheus for the `metrics` compose profile without a registry: Debian's package on the local
# base image (scripts/docker-build.sh builds it as lightfarm-prometheus:local). With a registry,
# set PROMETHEUS_IMAGE=prom/prometheus:latest in deploy/.env instead; the compose file's
# arguments suit both.
ARG BASE=lightfarm-base:trixie
FROM ${BASE}
RUN apt-get update -qq \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends prometheus >/dev/null \
 && apt-get clean && rm -rf /var/lib/apt/lists/* \
 && mkdir -p /prometheus
ENTRYPOINT ["/usr/bin/prometheus"]
