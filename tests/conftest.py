"""Shared fixtures: where the paper's published models are, and our own examples."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
SHARED = ROOT.parent / "shared" / "robosim"


@pytest.fixture
def published() -> Path:
    """The paper's models, read unchanged from ../shared (absent in a user's fresh clone)."""
    if not (SHARED / "ur5e" / "ur5e_gripper.rst").is_file():
        pytest.skip(f"the paper's published models are not at {SHARED} (only in the project workspace)")
    return SHARED


@pytest.fixture
def ur5e_example() -> Path:
    return EXAMPLES / "ur5e"


@pytest.fixture
def check_texts(tmp_path):
    """Write model texts into a fresh folder and check them as one project."""
    from cotwin.robosim.check import check_paths

    def run(files: dict[str, str]):
        for name, text in files.items():
            (tmp_path / name).write_text(text)
        return check_paths([tmp_path])

    return run
