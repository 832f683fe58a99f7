#!/usr/bin/env bash
# Per-cell time of `fast` vs the paper's SDR+SCA on the same instances, measured in one run.
# Needs the sdp feature's system libraries (libopenblas-dev, libgfortran-12-dev).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --release --quiet --features sdp --example solver_ratio -- "$@"
