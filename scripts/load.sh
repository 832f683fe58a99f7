#!/usr/bin/env bash
# Load test: path queries on the cached paper single-user map, over loopback only, bounded in
# time. Starts the release server on a free port, warms the map, runs wrk, stops the server.
#   scripts/load.sh [DURATION_S=20] [CONNECTIONS=32] [THREADS=2]
# Environment: IRS_BIN, a server binary to test instead of this checkout's release build (to
# compare two builds in one run); PHASE_PRECISION and PHASE_FORMAT, the queries' phase_precision
# and phase_format (the server's defaults when unset); DISTINCT=1 makes every query a new one
# (thresholds −62 − k·10⁻⁹ dB, the same path), so none is answered from the answer cache;
# DISTINCT=random draws every query's start and goal uniformly over the room, with a tolerance
# of TOLERANCE m (default 2: an end in an obstacle or below the threshold moves to the nearest
# usable cell, as a fleet's goals do; 0 leaves the ends as drawn), and its threshold uniformly
# in [THRESHOLD_LOW, THRESHOLD_HIGH] dB
# (default −66 to −60: from nearly every free cell feasible to a third of them not); on the
# 1001² floor 89 % of them have a path, of 570 waypoints on average. RESOLUTION (m) builds the map at another grid step than the
# scenario's 0.5 m (0.02: the 1001² floor). The answer's size is printed before the figures.
set -euo pipefail
cd "$(dirname "$0")/.."
duration=${1:-20}; connections=${2:-32}; threads=${3:-2}
command -v wrk >/dev/null || { apt-get update -qq && apt-get install -y -qq wrk >/dev/null; }
binary=${IRS_BIN:-}
if [ -z "$binary" ]; then cargo build --release --quiet; binary=./target/release/irs-planner; fi
log=$(mktemp); lua=$(mktemp --suffix=.lua)
RUST_LOG=warn "$binary" serve --bind 127.0.0.1:0 >"$log" 2>/dev/null &
server=$!
trap 'kill $server 2>/dev/null || true; rm -f "$log" "$lua"' EXIT
for _ in $(seq 100); do grep -q listening "$log" && break; sleep 0.1; done
url=$(sed -n 's/^listening on //p' "$log")
if [ -n "${RESOLUTION:-}" ]; then
  sid=$(python3 -c "import json,sys; d=json.load(open('scenarios/paper-single-user.json')); d['grid']['resolution_m']=$RESOLUTION; d['name']='paper-single-user-load'; print(json.dumps(d))" \
    | curl -sf -X POST "$url/v1/scenarios" -H 'content-type: application/json' -d @- | python3 -c "import json,sys; print(json.load(sys.stdin)['id'])")
else
  sid=$(curl -s "$url/v1/scenarios" | python3 -c "import json,sys; print([s['id'] for s in json.load(sys.stdin)['scenarios'] if s['name']=='paper-single-user'][0])")
fi
made=$(curl -s -X POST "$url/v1/maps" -H 'content-type: application/json' -d "{\"scenario_id\":\"$sid\",\"kind\":\"gain\"}")
map=$(echo "$made" | python3 -c "import json,sys; print(json.load(sys.stdin)['map_id'])")
# A large map is built as a job: wait until it is done.
job=$(echo "$made" | python3 -c "import json,sys; print(json.load(sys.stdin).get('job_id') or '')")
while [ -n "$job" ]; do
  state=$(curl -s "$url/v1/jobs/$job" | python3 -c "import json,sys; print(json.load(sys.stdin)['state'])")
  case $state in done) break ;; failed|cancelled) echo "the map's build $state" >&2; exit 1 ;; esac
  sleep 0.2
done
precision=${PHASE_PRECISION:+,\"phase_precision\":\"$PHASE_PRECISION\"}
format=${PHASE_FORMAT:+,\"phase_format\":\"$PHASE_FORMAT\"}
body="{\"map_id\":\"$map\",\"start\":[-10,0],\"goal\":[10,0],\"threshold\":-62$precision$format}"
bytes=$(curl -sf -X POST "$url/v1/paths" -H 'content-type: application/json' -d "$body" | wc -c)
echo "answer: $bytes bytes"
cat >"$lua" <<LUA
wrk.method = "POST"
wrk.body = '$body'
wrk.headers["Content-Type"] = "application/json"
LUA
if [ "${DISTINCT:-0}" = random ]; then
  low=${THRESHOLD_LOW:--66}; high=${THRESHOLD_HIGH:--60}; tolerance=${TOLERANCE:-2}
  # Each wrk thread draws from its own seed.
  cat >>"$lua" <<LUA
local threads = 0
setup = function(thread) threads = threads + 1; thread:set("seed", threads) end
init = function() math.randomseed(seed) end
local function at() return string.format("%.4f,%.4f", math.random() * 20 - 10, math.random() * 20 - 10) end
request = function()
  local body = string.format('{"map_id":"$map","start":[%s],"goal":[%s],"threshold":%.9f,"tolerance_m":$tolerance$precision$format}',
    at(), at(), $low + math.random() * ($high - $low))
  return wrk.format(nil, nil, nil, body)
end
LUA
elif [ "${DISTINCT:-0}" = 1 ]; then
  # Each wrk thread numbers its queries from its own offset, so no two are alike.
  cat >>"$lua" <<LUA
local count, threads = 0, 0
setup = function(thread) threads = threads + 1; thread:set("offset", threads * 1e7) end
request = function()
  count = count + 1
  local threshold = string.format("%.9f", -62 - (offset + count) * 1e-9)
  return wrk.format(nil, nil, nil, (wrk.body:gsub('"threshold":%-62', '"threshold":' .. threshold)))
end
LUA
fi
cat >>"$lua" <<LUA
done = function(summary, latency, requests)
  io.write(string.format("requests/s %.0f  p50 %.2f ms  p99 %.2f ms  max %.2f ms  errors %d\n",
    summary.requests / (summary.duration / 1e6), latency:percentile(50) / 1000,
    latency:percentile(99) / 1000, latency.max / 1000,
    summary.errors.status + summary.errors.connect + summary.errors.read + summary.errors.write + summary.errors.timeout))
end
LUA
wrk -t"$threads" -c"$connections" -d"${duration}s" --latency -s "$lua" "$url/v1/paths"
