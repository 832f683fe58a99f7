#!/usr/bin/env bash
# This crate against vectorised NumPy and SciPy on the same three workloads, in one run: the
# paper floor's continuous gain map at 2 cm (1001 × 1001 cells), the shortest path through
# a 19-wall serpentine maze on the same grid (and at 10 cm, 201 × 201), and an IRS placement search over the paper floor's
# walls (164 poses). Each side checks that the other computed the same thing (map values and
# scores to 1e-9 dB, path length to 1e-9 m) before any time is printed.
#   scripts/vs-python.sh [REPEATS=7]
# Installs numpy and scipy with pip when missing. NumPy's elementwise loops run on one thread,
# so the Rust figure to compare the map with is the one-thread one (printed beside the two-thread
# one). OPENBLAS_CORETYPE does not matter here: neither workload calls BLAS.
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=${1:-7}
python3 -c 'import numpy, scipy' 2>/dev/null ||
  python3 -m pip install --quiet --disable-pip-version-check numpy scipy
cargo build --release --quiet --example python_comparison
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
rust="${CARGO_TARGET_DIR:-target}/release/examples/python_comparison"
"$rust" gain "$out" "$repeats" >"$out/gain.json"
"$rust" maze "$out" "$repeats" >"$out/maze.json"
"$rust" maze-coarse "$out" "$repeats" >"$out/maze-coarse.json"
"$rust" place "$out" "$repeats" >"$out/place.json"
python3 scripts/vs_python.py "$out/gain.json" "$out/maze.json" "$out/maze-coarse.json" \
  "$out/place.json" "$out" "$repeats"
