# Two stages: build the release binary, then run it on a slim Debian with the scenarios.
#   docker build -t irs-planner .
#   docker run -p 8080:8080 irs-planner
# Enable the paper's SDR+SCA solver with --build-arg FEATURES=sdp (adds OpenBLAS).
FROM rust:1-bookworm AS build
ARG FEATURES=""
RUN if [ -n "$FEATURES" ]; then apt-get update && apt-get install -y --no-install-recommends libopenblas-dev libgfortran-12-dev; fi
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY src src
COPY benches benches
COPY examples examples
COPY scenarios scenarios
RUN cargo build --release --locked --features "$FEATURES" --bin irs-planner

FROM debian:bookworm-slim
ARG FEATURES=""
RUN if [ -n "$FEATURES" ]; then apt-get update && apt-get install -y --no-install-recommends libopenblas0 libgfortran5 && rm -rf /var/lib/apt/lists/*; fi \
 && useradd --system --uid 10001 irs
COPY --from=build /src/target/release/irs-planner /usr/local/bin/irs-planner
COPY scenarios /srv/scenarios
USER irs
ENV IRS_BIND=0.0.0.0:8080 IRS_SCENARIOS=/srv/scenarios IRS_LOG_FORMAT=json
EXPOSE 8080
# Liveness: GET /healthz; readiness: GET /readyz; metrics: GET /metrics.
ENTRYPOINT ["irs-planner"]
CMD ["serve"]
