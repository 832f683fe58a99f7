# Two stages: build the release binary, then run it on a slim Debian with the scenarios.
#   docker build -t irs-planner .
#   docker run -p 8080:8080 -v irs-data:/var/lib/irs-planner irs-planner
# Enable the paper's SDR+SCA solver with --build-arg FEATURES=sdp (adds OpenBLAS).
# Without a registry, scripts/base-images.sh makes both base images from Debian's packages.
FROM rust:1-bookworm AS build
ARG FEATURES=""
RUN if [ -n "$FEATURES" ]; then apt-get update && apt-get install -y --no-install-recommends libopenblas-dev libgfortran-12-dev; fi
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src src
COPY crates crates
COPY benches benches
COPY examples examples
COPY scenarios scenarios
# No debug line tables and a stripped binary in the image (the repository's release profile
# keeps line tables for profiling): 9 MB instead of 60.
ENV CARGO_PROFILE_RELEASE_DEBUG=0 CARGO_PROFILE_RELEASE_STRIP=true
RUN cargo build --release --locked --features "$FEATURES" --bin irs-planner

FROM debian:bookworm-slim
ARG FEATURES=""
# The package's version (Cargo.toml; the container test checks they agree) and the commit
# built (`--build-arg REVISION=$(git rev-parse HEAD)`).
ARG VERSION=0.1.0
ARG REVISION=unknown
LABEL org.opencontainers.image.title="irs-planner" \
      org.opencontainers.image.description="Radio maps and communication-aware robot paths with intelligent reflecting surfaces: an HTTP planning service" \
      org.opencontainers.image.version="$VERSION" \
      org.opencontainers.image.revision="$REVISION" \
      org.opencontainers.image.licenses="MIT"
# Any uid may run it (`docker run --user 12345:0`, as OpenShift does): the data directory
# belongs to group 0 with the owner's rights, and every uid runs with group 0 there.
RUN if [ -n "$FEATURES" ]; then apt-get update && apt-get install -y --no-install-recommends libopenblas0 libgfortran5 && rm -rf /var/lib/apt/lists/*; fi \
 && useradd --system --uid 10001 --gid 0 --no-create-home irs \
 && mkdir -p /var/lib/irs-planner && chown irs:0 /var/lib/irs-planner && chmod 0770 /var/lib/irs-planner
COPY --from=build /src/target/release/irs-planner /usr/local/bin/irs-planner
COPY scenarios /srv/scenarios
USER irs
# Scenarios registered through the API, built maps and finished jobs persist in the volume.
ENV IRS_BIND=0.0.0.0:8080 IRS_SCENARIOS=/srv/scenarios IRS_LOG_FORMAT=json \
    IRS_DATA_DIR=/var/lib/irs-planner
VOLUME /var/lib/irs-planner
EXPOSE 8080
# Liveness for Docker: the binary GETs its own /healthz (no curl in the image). Readiness for a
# load balancer: GET /readyz; metrics: GET /metrics.
HEALTHCHECK --interval=10s --timeout=5s --start-period=5s --retries=3 \
  CMD ["irs-planner", "healthcheck", "--timeout-s", "3"]
# The server is PID 1 and handles SIGTERM itself (docker stop): it stops accepting, lets
# running work finish for --shutdown-grace-s (5 s), then exits, within docker's 10 s.
STOPSIGNAL SIGTERM
ENTRYPOINT ["irs-planner"]
CMD ["serve"]
