"""Builds the package with `irs_planner_client` generated at build time from the repository's
openapi.yaml (two directories up) by the pinned openapi-python-client, with its default
settings: the client always matches the contract it is built beside, and no generated code is
kept in the repository. Everything else is in pyproject.toml."""

import pathlib
import shutil
import subprocess
import sys
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = pathlib.Path(__file__).resolve().parent
CONTRACT = HERE.parents[1] / "openapi.yaml"


class BuildWithGeneratedClient(build_py):
    def run(self):
        super().run()
        if not CONTRACT.is_file():
            sys.exit(f"{CONTRACT} not found: build the package from a checkout of irs-planner")
        target = pathlib.Path(self.build_lib) / "irs_planner_client"
        shutil.rmtree(target, ignore_errors=True)
        with tempfile.TemporaryDirectory() as scratch:
            out = pathlib.Path(scratch) / "irs_planner_client"
            subprocess.run(
                [sys.executable, "-m", "openapi_python_client", "generate", "--path", str(CONTRACT),
                 "--output-path", str(out), "--meta", "none"],
                check=True, stdout=subprocess.DEVNULL)
            shutil.copytree(out, target)


setup(cmdclass={"build_py": BuildWithGeneratedClient})
