"""MuJoCo's sensors computed only in the physics steps after which they are read.

cotwin reads a simulator's sensors after a stretch of physics steps (a communication step, a control period),
never between them, and a sensor feeds nothing back into the dynamics; MuJoCo computes every sensor in every
mj_step all the same. The native loops (cotwin.mapping.native's control loop, cotwin.pmodel.memo's held steps)
set mjDSBL_SENSOR for all but a stretch's last step: the states are the same, bit for bit, and so are the
readings (tests/test_sensing.py); with a robot arm's joint sensors a step costs a few per cent less.

They write the flag through its address in the model (`flags_address`), found with the offsets of MuJoCo's
installed headers and checked against the model before use; None where the headers are not installed, where
the model has plugins (they may keep state or read sensors between steps) or user sensors (a callback
computes them), or where the user has turned sensors off already: then every step computes them, as before. Sensors the user
turns off later, on the model, stay off: `PlatformSimulator.sensor_flags` gives no address while they are off,
and it is asked before each stretch (every step as the user has it).
"""

from __future__ import annotations

import ctypes

import mujoco

from .mujoco_c import model_functions

SENSOR = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)

def flags_address(model: mujoco.MjModel) -> int | None:
    """The address of `model`'s opt.disableflags for a native loop to skip sensors between reads (see the module
    doc), or None where it must not."""
    functions = model_functions()
    if functions is None or model.opt.disableflags & SENSOR:
        return None
    kinds = set(model.sensor_type.tolist())
    if model.nplugin or int(mujoco.mjtSensor.mjSENS_PLUGIN) in kinds or int(mujoco.mjtSensor.mjSENS_USER) in kinds:
        return None  # a plugin may read sensors between steps; a user sensor is a callback's
    offset = functions[0]
    flags = ctypes.c_int.from_address(model._address + offset)
    before = model.opt.disableflags
    if flags.value != before:
        return None
    model.opt.disableflags = before | SENSOR  # the address is the field's: a change through the model is seen there
    seen = flags.value
    model.opt.disableflags = before
    return model._address + offset if seen == before | SENSOR and flags.value == before else None
