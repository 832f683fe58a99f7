#!/usr/bin/env python3
"""Runs the Python examples of docs/clients.md against a running server, with the clients CI
generated, so the page cannot drift from the generators or the contract:

    python3 tests/clients/docs_examples.py URL DIR_OF_irs_planner_client DIR_OF_irs_planner_openapi

Each ```python block runs as written, with the page's server address replaced by URL."""

import pathlib
import re
import sys
import traceback

url, *client_dirs = sys.argv[1:]
sys.path[:0] = client_dirs
page = pathlib.Path(__file__).resolve().parents[2] / "docs" / "clients.md"
blocks = re.findall(r"```python\n(.*?)```", page.read_text(), re.S)
failed = 0
for k, block in enumerate(blocks, 1):
    try:
        exec(block.replace("http://127.0.0.1:8080", url.rstrip("/")), {})
        print(f"ok   docs/clients.md example {k}")
    except Exception:
        failed += 1
        print(f"FAIL docs/clients.md example {k}\n{traceback.format_exc()}")
print(f"{len(blocks) - failed} passed, {failed} failed")
sys.exit(1 if failed or not blocks else 0)
