"""MuJoCo's C library and headers as the mujoco module installed them, for cotwin's native code.

The native loops call MuJoCo's functions by address (`address`: from the library the module loaded, so both
use one copy of MuJoCo), and read its structs through the installed headers (`include_dir`, None where the
wheel has none). `model_functions` is one small library built against those headers: where opt.disableflags
lies in an mjModel (cotwin.pmodel.sensing) and a digest of a model's numbers (cotwin.pmodel.memo).
"""

from __future__ import annotations

import ctypes
import functools
from pathlib import Path

import mujoco

FOLDER = Path(mujoco.__file__).parent

_MODEL = r"""
#include <stddef.h>
#include <string.h>
#include <mujoco/mjmodel.h>
/* MuJoCo @VERSION@ */

/* where opt.disableflags lies in an mjModel */
size_t cotwin_flags_offset(void) { return offsetof(mjModel, opt) + offsetof(mjOption, disableflags); }

/* a digest of everything a model's steps read: its buffer of arrays and its options (four lanes of words, each
   its own chain of multiplications, so that they overlap: the digest is made before every native stretch) */
unsigned long long cotwin_model_digest(const mjModel *m) {
    unsigned long long h[4] = {1469598103934665603ULL, 7809847782465536322ULL, 10723151780598845931ULL,
                               3162461265461853237ULL}, word[4];
    const unsigned char *parts[2] = {(const unsigned char *)m->buffer, (const unsigned char *)&m->opt};
    size_t sizes[2] = {(size_t)m->nbuffer, sizeof(mjOption)};
    for (int p = 0; p < 2; p++) {
        size_t i = 0;
        for (; i + sizeof word <= sizes[p]; i += sizeof word) {
            memcpy(word, parts[p] + i, sizeof word);
            for (int k = 0; k < 4; k++) {
                h[k] = (h[k] ^ word[k]) * 1099511628211ULL;
                h[k] ^= h[k] >> 29;
            }
        }
        for (; i < sizes[p]; i++) h[0] = (h[0] ^ parts[p][i]) * 1099511628211ULL;
        h[1] ^= (unsigned long long)sizes[p];  /* where one part ends and the next begins */
    }
    unsigned long long out = h[0];
    for (int k = 1; k < 4; k++) {
        out = (out ^ h[k]) * 1099511628211ULL;
        out ^= out >> 29;
    }
    return out;
}
"""


@functools.lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    libraries = sorted(FOLDER.glob("libmujoco.so*"))
    return ctypes.CDLL(str(libraries[0])) if libraries else None


def address(name: str) -> int | None:
    """The address of MuJoCo's C function `name` in the library the mujoco module loaded, or None."""
    library = _library()
    return ctypes.cast(library[name], ctypes.c_void_p).value if library is not None else None


def include_dir(header: str = "mjmodel.h") -> str | None:
    """The folder holding the installed version's `mujoco/<header>`, or None where it is not installed."""
    folder = FOLDER / "include"
    return str(folder) if (folder / "mujoco" / header).is_file() else None


@functools.lru_cache(maxsize=1)
def model_functions() -> tuple[int, ctypes._CFuncPtr] | None:
    """(the offset of opt.disableflags in an mjModel, the model digest function), built once against the
    installed headers; None where they are not installed or nothing compiles here."""
    from ..cbuild import compile_library

    folder = include_dir()
    if folder is None:
        return None
    try:
        lib = compile_library(_MODEL.replace("@VERSION@", mujoco.__version__), "mujoco-model", keep_gil=False,
                              include_dirs=(folder,))
    except (ValueError, OSError):
        return None
    offset, digest = lib.cotwin_flags_offset, lib.cotwin_model_digest
    offset.restype = ctypes.c_size_t
    digest.argtypes, digest.restype = [ctypes.c_void_p], ctypes.c_ulonglong
    return int(offset()), digest
