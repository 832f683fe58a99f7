#!/usr/bin/env python3
"""One tenant floods the scenario registry with inline-scenario maps; then another tenant
registers a scenario. Measures that every map of the flood is answered and how long the other
tenant's registration takes (issue 30: nobody can lock the registry).

    scripts/registry-flood.py BINARY [MAPS]     (default 1100 maps; --max-scenarios 1000)

Starts `BINARY serve` with two tokens on a loopback port, prints one line of figures, exits 1
if a map of the flood or the other registration is refused. Standard-library Python only.
"""

import pathlib
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests" / "support"))
import irs_testkit as kit  # noqa: E402


def main():
    binary, maps = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 1100
    alice, bob = "alice-flood-token-0001", "bob-flood-token-000002"
    server = kit.Server(binary, "--scenarios", tempfile.mkdtemp(prefix="irs-flood-"),
                        "--api-tokens", f"{alice},{bob}", timeout=60)
    try:
        statuses = {}
        started = time.perf_counter()
        for k in range(maps):
            doc = kit.scenario("small-test", lambda d, k=k: d.update(name=f"flood-{k}"))
            status, _, _ = server.post("/v1/maps", {"scenario": doc, "kind": "gain"}, token=alice)
            statuses[status] = statuses.get(status, 0) + 1
        flood_s = time.perf_counter() - started
        timings = []
        for k in range(5):
            doc = kit.scenario("small-test", lambda d, k=k: d.update(name=f"bob-{k}"))
            started = time.perf_counter()
            status, _, _ = server.post("/v1/scenarios", doc, token=bob)
            timings.append(((time.perf_counter() - started) * 1000, status))
        evicted = server.metric("irs_scenarios_evicted_total")
        print(f"{maps} inline-scenario maps from one token: statuses {statuses} in {flood_s:.1f} s "
              f"({evicted:.0f} scenarios evicted); then another token's registrations: "
              + ", ".join(f"{s} in {ms:.1f} ms" for ms, s in timings))
        ok = statuses == {200: maps} and all(s == 201 for _, s in timings)
        return 0 if ok else 1
    finally:
        server.stop()


if __name__ == "__main__":
    sys.exit(main())
