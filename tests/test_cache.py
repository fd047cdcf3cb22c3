"""`cotwin cache [--clear]` (cotwin.cache): where the cache is, what it holds per kind, and clearing it without
ever removing what cotwin did not write."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cache_entries import entry


def cotwin(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cotwin", *map(str, args)], capture_output=True, text=True, timeout=120)


@pytest.fixture
def root(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv("COTWIN_CACHE", str(folder))
    monkeypatch.delenv("COTWIN_CACHE_MAX_MB", raising=False)
    return folder


# ---- the command ---------------------------------------------------------------------------------

def test_the_command_shows_where_the_cache_is_its_size_and_entries_per_kind(root):
    for n in range(3):
        entry(root, "native", n, 1024)
    entry(root, "binaries", 1, 2048)
    entry(root, "fmu", 1, 4096)
    entry(root, "ik", 1, 100)
    (root / "ik" / f"{1:032x}.json.lock").write_bytes(b"")
    proc = cotwin("cache")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == f"{root}: 9.1 KiB, at most 512 MiB (COTWIN_CACHE_MAX_MB)"
    assert [line.split()[:2] for line in lines[1:5]] == [["native/", "3"], ["binaries/", "1"], ["fmu/", "1"], ["ik/", "1"]]
    assert lines[1].endswith("3 KiB") and lines[3].endswith("4 KiB")


def test_the_command_says_there_is_no_cache_when_it_is_off_or_not_made(root, monkeypatch):
    proc = cotwin("cache")
    assert proc.returncode == 0 and proc.stdout.startswith(f"{root} (not made yet): 0 bytes")
    monkeypatch.setenv("COTWIN_CACHE", "off")
    proc = cotwin("cache")
    assert proc.returncode == 0 and "COTWIN_CACHE=off" in proc.stdout


def test_clear_removes_cotwins_entries_and_the_emptied_folders(root):
    entry(root, "native", 1), entry(root, "binaries", 1), entry(root, "fmu", 1), entry(root, "ik", 1)
    proc = cotwin("cache", "--clear")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"{root}: removed 4 entries")
    assert not root.exists()
    proc = cotwin("cache", "--clear")  # nothing there: nothing to do
    assert proc.returncode == 0 and "removed 0 entries" in proc.stdout


def test_clear_refuses_a_folder_holding_files_cotwin_did_not_write_and_removes_nothing(root):
    """COTWIN_CACHE=~ (or a project folder) by mistake: --clear must not delete what cotwin did not write."""
    ours = entry(root, "native", 1)
    notes = root / "notes.txt"
    notes.write_text("mine")
    odd = root / "fmu" / "photos"  # a name cotwin does not write, inside a kind's folder
    odd.mkdir(parents=True)
    proc = cotwin("cache", "--clear")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith(f"{root}: error: not cotwin's cache alone: it holds 2 file(s) cotwin did not write "
                                  "(fmu/photos, notes.txt)")
    assert ours.is_file() and notes.is_file() and odd.is_dir()
    shown = cotwin("cache")  # shown, with what is not cotwin's said
    assert shown.returncode == 0 and "also 2 file(s) cotwin did not write" in shown.stdout


@pytest.mark.parametrize("setting", ["a file", "off"])
def test_clear_refuses_a_cache_that_is_a_file_or_off(root, monkeypatch, setting):
    if setting == "off":
        monkeypatch.setenv("COTWIN_CACHE", "off")
        where = "COTWIN_CACHE"
    else:
        root.write_text("not a folder")
        where = str(root)
    proc = cotwin("cache", "--clear")
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith(f"{where}: error: ")
    assert setting == "off" or root.read_text() == "not a folder"


def test_clear_removes_a_partial_folder_a_killed_process_left_without_leaving_one_of_no_name_of_cotwins(root,
                                                                                                     monkeypatch):
    """A folder left under a partial name (an extraction or a removal cut short) is cotwin's and is cleared. It was
    renamed again before its removal, to '..NAME...': had that removal failed, the folder bore no name of cotwin's,
    and every later --clear refused the cache as holding a foreign file."""
    import shutil

    from cotwin import cache

    left = entry(root, "fmu", 7)
    partial = left.with_name(f".{left.name}.4242.0")  # as a killed removal leaves it
    left.rename(partial)
    made = []
    real = shutil.rmtree
    monkeypatch.setattr(shutil, "rmtree", lambda path, ignore_errors=False: made.append(Path(path)))  # removal fails
    found = cache.contents(root)
    assert [e.path for e in found.entries] == [partial] and found.entries[0].partial
    assert cache.remove(found.entries[0])
    assert not cache.contents(root).foreign, made  # what a failed removal leaves is still cotwin's
    monkeypatch.setattr(shutil, "rmtree", real)
    proc = cotwin("cache", "--clear")
    assert proc.returncode == 0 and not root.exists(), proc.stdout + proc.stderr
