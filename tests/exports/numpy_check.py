"""The .npy export opens with numpy.load and holds the map's JSON values (CI: .ci/run).

usage: numpy_check.py BINARY SERVER_URL

The warehouse's gain map from the CLI (`map` and `export`) and from the server (`values.npy`):
shape (nx, ny), float32 of every JSON value, NaN exactly where the JSON has null, and the
server's file byte-identical to the CLI's.
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "support"))
import irs_testkit as kit  # noqa: E402

binary, base = sys.argv[1], sys.argv[2].rstrip("/")
scenario = "scenarios/warehouse/warehouse.json"
CHECKS = kit.Checks(stop_on_failure=True)
check = CHECKS.check


def main():
    body = json.loads(subprocess.run([binary, "map", "--scenario", scenario, "--kind", "gain", "--quiet"],
                                     check=True, capture_output=True).stdout)
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([binary, "export", "--scenario", scenario, "--kind", "gain", "--quiet",
                        "--threshold=-72", "--out", out], check=True, capture_output=True)
        cli_bytes = (Path(out) / "map.npy").read_bytes()
        a = numpy.load(Path(out) / "map.npy")

    nx, ny = body["grid"]["nx"], body["grid"]["ny"]
    check(a.shape == (nx, ny) and a.dtype == numpy.float32, f"shape {a.shape} = (nx, ny) = ({nx}, {ny}), float32")
    values = numpy.array([[numpy.nan if v is None else v for v in row] for row in body["values"]])
    check(numpy.array_equal(numpy.isnan(a), numpy.isnan(values)), f"NaN exactly at the {int(numpy.isnan(values).sum())} null cells")
    finite = ~numpy.isnan(values)
    check(numpy.array_equal(a[finite], values[finite].astype(numpy.float32)),
          f"a[i, j] = float32(values[i][j]) for all {int(finite.sum())} free cells")

    document = subprocess.run([binary, "scenario", "--scenario", scenario], check=True, capture_output=True).stdout
    scenario_id = kit.post(base, "/v1/scenarios", document, raise_for_status=True).body["id"]
    map_id = kit.post(base, "/v1/maps", {"scenario_id": scenario_id, "kind": "gain"}, raise_for_status=True).body["map_id"]
    check(map_id == body["map_id"], "the server's map id is the CLI's")
    served = kit.get(base, f"/v1/maps/{map_id}/values.npy", parse="bytes", raise_for_status=True).body
    check(served == cli_bytes, f"GET /values.npy is byte-identical to the CLI's map.npy ({len(served)} bytes)")


sys.exit(CHECKS.run(main))
