"""MuJoCo's sensors computed only in the physics steps after which they are read.

cotwin reads a simulator's sensors after a stretch of physics steps (a communication step, a control period),
never between them, and a sensor feeds nothing back into the dynamics; MuJoCo computes every sensor in every
mj_step all the same. The native loops (cotwin.mapping.native's control loop, cotwin.pmodel.memo's held steps)
set mjDSBL_SENSOR for all but a stretch's last step: the states are the same, bit for bit, and so are the
readings (tests/test_sensing.py); with a robot arm's joint sensors a step costs a few per cent less.

They write the flag through its address in the model (`flags_address`), found with the offsets of MuJoCo's
installed headers and checked against the model before use; None where the headers are not installed, where
the model has plugins (they may keep state or read sensors between steps) or user sensors (a callback
computes them), or where the user has turned sensors off already: then every step computes them, as before.
"""

from __future__ import annotations

import ctypes
import functools
import os

import mujoco

SENSOR = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)

_OFFSET = r"""
#include <stddef.h>
#include <mujoco/mjmodel.h>
/* MuJoCo %s */
size_t cotwin_flags_offset(void) { return offsetof(mjModel, opt) + offsetof(mjOption, disableflags); }
"""


@functools.lru_cache(maxsize=1)
def _offset() -> int | None:
    """The offset of opt.disableflags in the installed MuJoCo's mjModel, or None (no headers, no compiler)."""
    from ..cbuild import compile_library

    folder = os.path.join(os.path.dirname(mujoco.__file__), "include")
    if not os.path.isfile(os.path.join(folder, "mujoco", "mjmodel.h")):
        return None
    try:
        lib = compile_library(_OFFSET % mujoco.__version__, "flags-offset", keep_gil=False, include_dirs=(folder,))
    except (ValueError, OSError):
        return None
    fn = lib.cotwin_flags_offset
    fn.restype = ctypes.c_size_t
    return int(fn())


def flags_address(model: mujoco.MjModel) -> int | None:
    """The address of `model`'s opt.disableflags for a native loop to skip sensors between reads (see the module
    doc), or None where it must not."""
    offset = _offset()
    if offset is None or model.opt.disableflags & SENSOR:
        return None
    kinds = set(model.sensor_type.tolist())
    if model.nplugin or int(mujoco.mjtSensor.mjSENS_PLUGIN) in kinds or int(mujoco.mjtSensor.mjSENS_USER) in kinds:
        return None  # a plugin may read sensors between steps; a user sensor is a callback's
    flags = ctypes.c_int.from_address(model._address + offset)
    before = model.opt.disableflags
    if flags.value != before:
        return None
    model.opt.disableflags = before | SENSOR  # the address is the field's: a change through the model is seen there
    seen = flags.value
    model.opt.disableflags = before
    return model._address + offset if seen == before | SENSOR and flags.value == before else None
