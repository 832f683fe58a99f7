#!/usr/bin/env python3
"""The contract with the body-carrying links of stateful-links.yaml added, as JSON:

    python3 tests/contract/with_links.py openapi.yaml tests/contract/stateful-links.yaml OUT.json

JSON out, so every value keeps the type the YAML gave it (a YAML writer could turn the string
"1e-2" into a plain scalar that another reader takes for a number). Refuses a link that already
exists or a response that does not, so the overlay cannot drift from the contract silently."""

import json
import sys

import yaml

contract_path, overlay_path, out_path = sys.argv[1:4]
with open(contract_path) as f:
    contract = yaml.safe_load(f)
with open(overlay_path) as f:
    overlay = yaml.safe_load(f)
added = 0
for path, methods in overlay.items():
    for method, statuses in methods.items():
        for status, links in statuses.items():
            response = contract["paths"][path][method]["responses"][status]
            existing = response.setdefault("links", {})
            for name, link in links.items():
                if name in existing:
                    sys.exit(f"{path} {method} {status}: the contract already has link {name}")
                existing[name] = link
                added += 1
with open(out_path, "w") as f:
    json.dump(contract, f)
print(f"{added} links added")
