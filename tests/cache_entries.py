"""Made-up entries of cotwin's cache, named as cotwin names them (tests/test_cache*.py)."""

from __future__ import annotations

import os
import time
from pathlib import Path

HOUR = 3600.0


def entry(root: Path, kind: str, n: int, size: int = 1000, age: float = HOUR) -> Path:
    """A made-up entry of `kind` (named as cotwin names them), `size` bytes, last used `age` seconds ago."""
    if kind == "native":
        path = root / "native" / f"segment-{n:020x}.so"
    elif kind == "binaries":
        path = root / "binaries" / f"{n:064x}.so"
    elif kind == "ik":
        path = root / "ik" / f"{n:032x}.json"
    else:
        path = root / "fmu" / f"{n:024x}"
        (path / "binaries" / "linux64").mkdir(parents=True)
        (path / "modelDescription.xml").write_text("<fmiModelDescription/>")
        (path / "binaries" / "linux64" / "m.so").write_bytes(b"\0" * (size - 22))
    if kind != "fmu":
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"\0" * size)
    stamp = time.time() - age
    os.utime(path, (stamp, stamp))
    return path
