"""Shared fixtures: the real logs beside the repository and the `qicp` command line."""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data"
INTEL = DATA / "intel" / "intel.clf.bz2"
INTEL_RELATIONS = DATA / "intel" / "intel.relations"


@pytest.fixture(scope="session")
def qicp_bin() -> pathlib.Path:
    """The `qicp` binary the Python results are compared with (QICP_BIN, else the release
    build of this repository, which `cargo test --release` leaves behind)."""
    path = pathlib.Path(os.environ.get("QICP_BIN", REPO / "target" / "release" / "qicp"))
    if not path.is_file():
        pytest.fail(f"no qicp binary at {path}: run `cargo build --release` or set QICP_BIN")
    return path


@pytest.fixture(scope="session")
def intel() -> pathlib.Path:
    if not INTEL.is_file():
        pytest.fail(f"the Intel log is missing: {INTEL} (../shared/data beside the repository)")
    return INTEL


def run_cli(qicp_bin, *args) -> subprocess.CompletedProcess:
    return subprocess.run([str(qicp_bin), *map(str, args)], capture_output=True, text=True)
