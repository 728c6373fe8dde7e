"""Shared fixtures: the repository's examples and test data, and the `cpm` command."""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
MALFORMED = ROOT / "tests" / "data" / "malformed"
HEXAPOD = EXAMPLES / "hexapod_66.toml"
HEXAPOD_READINGS = EXAMPLES / "hexapod_66_readings.csv"
CUBE = EXAMPLES / "paper_cubic.toml"


@pytest.fixture(scope="session")
def cpm_bin() -> Path:
    """The `cpm` command of this checkout (CPM_BIN, else target/debug/cpm, built if
    missing)."""
    env = os.environ.get("CPM_BIN")
    if env:
        return Path(env)
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    b = target / "debug" / "cpm"
    if not b.exists():
        subprocess.run(["cargo", "build", "--bin", "cpm"], cwd=ROOT, check=True)
    assert b.exists(), b
    return b


@pytest.fixture
def in_root(monkeypatch):
    """Runs the test in the repository root (files named as the Rust tests name them)."""
    monkeypatch.chdir(ROOT)
    return ROOT
