"""Shared fixtures of the Python tests: the ambid CLI (the parity reference) and scratch dirs.

`AMBID_CLI` names the command-line binary built from the same checkout (`.ci/run` sets it to
`target/debug/ambid`). Without it the parity tests are skipped, and the skip is recorded in
`$AMBID_SKIP_LOG` (the list `.ci/run` prints); under `CI` a missing CLI is a failure.
"""

import os
import subprocess

import pytest

REAL = os.path.join(os.path.dirname(__file__), "..", "..", "..", "..", "shared", "data", "real")


def _skip(reason: str):
    log = os.environ.get("AMBID_SKIP_LOG")
    if log:
        os.makedirs(os.path.dirname(log), exist_ok=True)
        with open(log, "a", encoding="utf-8") as fh:
            fh.write(f"python: {reason}\n")
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (CI is set: a skipped check is a failure)")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def cli():
    exe = os.environ.get("AMBID_CLI")
    if not exe or not os.path.exists(exe):
        _skip("AMBID_CLI is not set to the ambid binary: the CLI parity checks were not run")

    def call(*args, cwd=None):
        res = subprocess.run([exe, *map(str, args)], cwd=cwd, capture_output=True, text=True)
        if res.returncode != 0:
            raise AssertionError(f"ambid {' '.join(map(str, args))} failed:\n{res.stderr}")
        return res

    return call


@pytest.fixture(scope="session")
def real_data():
    path = os.path.abspath(os.environ.get("AMBID_REAL_DATA", REAL))
    if not os.path.isdir(path):
        _skip(f"the real data sets are not at {path}: the real-data parity check was not run")
    return path


def skip_visibly(reason: str):
    _skip(reason)
