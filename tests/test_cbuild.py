"""cotwin.cbuild: a native library is built and loaded whatever state cotwin's cache is in."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from cotwin import cbuild

SOURCE = "int cotwin_answer(void) { return 42; }\n"


@pytest.mark.skipif(cbuild.compiler() is None, reason="no C compiler")
@pytest.mark.parametrize("cache", ["writable", "read-only", "a file"])
def test_a_library_is_built_and_loaded_whether_or_not_the_cache_can_be_written(tmp_path, monkeypatch, cache):
    """The cache is an optimisation: a read-only cache folder, or COTWIN_CACHE naming a file, failed every
    'cotwin run' ('error: Not a directory: .../native'); the library is kept in a temporary folder instead."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    folder = tmp_path / "cache"
    if cache == "a file":
        folder.write_text("not a folder")
    monkeypatch.setenv("COTWIN_CACHE", str(folder))
    if cache == "read-only":  # chmod 555 does not stop root, who may run the tests: the refusal made by hand
        made = Path.mkdir

        def refused(path, *args, **kwargs):
            if str(path).startswith(str(folder)):
                raise PermissionError(13, "Permission denied", str(path))
            return made(path, *args, **kwargs)

        monkeypatch.setattr(Path, "mkdir", refused)
    for _ in range(2):  # built, then found where it was kept
        assert cbuild.compile_library(SOURCE, "answer").cotwin_answer() == 42
    kept = list((folder if cache == "writable" else tmp_path / "tmp").rglob("answer-*.so"))
    assert len(kept) == 1
