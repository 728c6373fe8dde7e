"""Shared fixtures: the repository's examples and test data, and the `cpm` command."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
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
    """The `cpm` command to compare with: CPM_BIN, else this checkout's target/debug/cpm
    (built with cargo when cargo is there), else the `cpm` script the wheel installed beside
    this Python (the same command, run by the extension: no Rust toolchain needed).
    CPM_NO_CHECKOUT_BIN=1 passes over the checkout's binary (`.ci/python_wheel`)."""
    env = os.environ.get("CPM_BIN")
    if env:
        return Path(env)
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    b = target / "debug" / "cpm"
    if b.exists() and not os.environ.get("CPM_NO_CHECKOUT_BIN"):
        return b
    if shutil.which("cargo"):
        subprocess.run(["cargo", "build", "--bin", "cpm"], cwd=ROOT, check=True)
        assert b.exists(), b
        return b
    script = Path(sys.executable).parent / "cpm"
    assert script.exists(), f"no cpm command: no {b}, no cargo, no {script}"
    return script


@pytest.fixture
def in_root(monkeypatch):
    """Runs the test in the repository root (files named as the Rust tests name them)."""
    monkeypatch.chdir(ROOT)
    return ROOT


def no_temp_folder(mp: pytest.MonkeyPatch) -> None:
    """Inside ``mp``'s context, any temporary file or folder made from Python (the scratch
    folders ``cpm`` once wrote robots and measurements to) fails the test."""
    import tempfile

    def made(*args, **kwargs):
        raise AssertionError("a temporary file or folder was made")

    for name in ("mkdtemp", "mkstemp", "TemporaryDirectory", "NamedTemporaryFile",
                 "TemporaryFile", "SpooledTemporaryFile"):
        mp.setattr(tempfile, name, made)
