"""What several test files share."""
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture
def binary():
    """The command-line binary `cargo test` builds (the test command runs it before these tests)."""
    for profile in ("debug", "release"):
        path = ROOT / "target" / profile / "locobench"
        if path.exists():
            return path
    pytest.fail("no target/debug/locobench: build it first (cargo build; scripts/test.sh does)")
