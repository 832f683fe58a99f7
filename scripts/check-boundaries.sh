#!/usr/bin/env bash
# The crate boundaries of docs/architecture.md, checked against cargo's dependency graph: the
# model (and the answers crate) must not reach a runtime, a front door or an output format.
set -euo pipefail
cd "$(dirname "$0")/.."
front_doors=(tokio axum hyper tower tower-http redis moka clap indicatif tracing-subscriber
  metrics metrics-exporter-prometheus reqwest)
formats=(serde_json base64 postcard serde-saphyr sha2 font8x8 npyz tar)
status=0
check() {
  local crate=$1; shift
  local tree
  tree=$(cargo tree -p "$crate" -e normal --prefix none --format '{p}' | awk '{print $1}' | sort -u)
  for banned in "$@"; do
    if grep -qx "$banned" <<<"$tree"; then
      echo "$crate depends on $banned (docs/architecture.md bans it):"
      cargo tree -p "$crate" -e normal -i "$banned" | head -n 20
      status=1
    fi
  done
}
check irs-model "${front_doors[@]}" "${formats[@]}"
check irs-answers "${front_doors[@]}"
[ "$status" = 0 ] && echo "boundaries hold: irs-model and irs-answers reach no banned crate"
exit "$status"
