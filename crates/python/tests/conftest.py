"""Shared fixtures: the repository's example scan and the dhct command line."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

import dhct

REPO = Path(__file__).resolve().parents[3]
EXAMPLE = REPO / "tests" / "data" / "simulated_graphite.sm4"


def _cli() -> Path:
    """The dhct binary: $DHCT_BIN, else target/{debug,release}/dhct, else built by cargo."""
    given = os.environ.get("DHCT_BIN")
    if given:
        path = Path(given)
        assert path.is_file(), f"DHCT_BIN={given} is not a file"
        return path
    for profile in ("debug", "release"):
        path = REPO / "target" / profile / "dhct"
        if path.is_file():
            return path
    if shutil.which("cargo") is None:
        pytest.skip("no dhct binary (set DHCT_BIN) and no cargo to build one")
    subprocess.run(["cargo", "build", "-p", "dhct-cli"], cwd=REPO, check=True)
    return REPO / "target" / "debug" / "dhct"


@pytest.fixture(scope="session")
def cli() -> Path:
    return _cli()


@pytest.fixture(scope="session")
def example() -> Path:
    assert EXAMPLE.is_file(), f"missing {EXAMPLE}"
    return EXAMPLE


@pytest.fixture(scope="session")
def scan(example):
    return dhct.read(example)


@pytest.fixture(scope="session")
def result(scan):
    return dhct.correct(scan)
