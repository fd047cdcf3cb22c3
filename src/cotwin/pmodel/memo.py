"""Held physics steps remembered by the state they start from: what a sweep's forks share after their start.

A sweep's what-ifs start from one state and, until their controllers act on their different commands (a
feasibility check, a move), hold the robot where it is: each fork makes the same physics steps from the same
MuJoCo state. MuJoCo's step is a function of the model and of its integration state (time, positions,
velocities, actuator states, warm start, controls, applied forces: mjSTATE_INTEGRATION, the state forks are
restored from), so n steps held from a state seen before end where they ended then. A `StepMemo` keeps, for
each such stretch (its state and its n), the state one step before its end: met again, that state is restored
and the last step made anew, which computes what is read after it (sensors, poses, contacts) as the first
stretch's last step did. The steps are the same, bit for bit; MuJoCo's diagnostics of the skipped steps
(warnings, solver counters, timers) are not repeated.

The C (`SOURCE`, inside the native loop: cotwin.mapping.cstep) looks a stretch up by a hash of its state and
compares the whole state; the memo keeps its first `capacity` stretches (a sweep's shared ones come first).
A memo's stretches are of the model as it was: the native loop checks a digest of the model's numbers (its
buffer and options, `model_digest`) before each stretch and clears the memo when they changed (a payload
given to the fork, a calibrated gain), and `PlatformSimulator.set_bodies` clears it at once. There is no memo
where MuJoCo keeps state outside the integration state (sleeping bodies, plugins) or where the digest cannot be
made (MuJoCo's headers not installed), and a memo keeps and takes nothing while its model's options, changed
since, let bodies sleep (`check`); only forks turn one on (cotwin.twin.services.whatif.Forks), on
simulators of their own.
"""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np

from .mujoco_c import address, model_functions
from .sensing import SENSOR

SOURCE = r"""
#include <string.h>
#ifndef COTWIN_DSBL_SENSOR
#define COTWIN_DSBL_SENSOR @SENSOR@  /* mjDSBL_SENSOR */
#endif

typedef void (*cotwin_get_state)(const void *, const void *, double *, int);  /* mj_getState */
typedef void (*cotwin_set_state)(const void *, void *, const double *, int);  /* mj_setState */

typedef struct {
    cotwin_get_state get;
    cotwin_set_state set;
    int sig, size, capacity, count, mask;  /* size: the state's numbers; mask: the table's size - 1 */
    double *keys;    /* capacity x (size + 1): each stretch's first state and its steps */
    double *states;  /* capacity x size: the state one step before each stretch's end */
    int *table;      /* mask + 1 slots: an entry's index, or -1 */
    double *scratch; /* size + 1 */
    long long hits, misses;
} cotwin_memo;

static unsigned long long cotwin_memo_hash(const double *x, int n) {
    unsigned long long h = 1469598103934665603ULL, word;
    for (int i = 0; i < n; i++) {
        memcpy(&word, x + i, sizeof word);
        h = (h ^ word) * 1099511628211ULL;
        h ^= h >> 29;
    }
    return h;
}

/* n physics steps, the sensors computed in the last only when `flags` (the model's opt.disableflags) is given
   (cotwin.pmodel.sensing) */
static void cotwin_steps(void (*step)(const void *, void *), const void *model, void *data, int n, int *flags) {
    if (flags && n > 1) {
        *flags |= COTWIN_DSBL_SENSOR;
        for (int k = 0; k < n - 1; k++) step(model, data);
        *flags &= ~COTWIN_DSBL_SENSOR;
        n = 1;
    }
    for (int k = 0; k < n; k++) step(model, data);
}

/* n physics steps with the servos holding their set-points, through `memo` when there is one (see
   cotwin.pmodel.memo). */
static void cotwin_held(void (*step)(const void *, void *), const void *model, void *data, int n,
                        cotwin_memo *memo, int *flags) {
    if (memo == NULL || n < 2) {
        cotwin_steps(step, model, data, n, flags);
        return;
    }
    int width = memo->size + 1;
    double *key = memo->scratch;
    memo->get(model, data, key, memo->sig);
    key[memo->size] = (double)n;
    int at = (int)(cotwin_memo_hash(key, width) & (unsigned long long)memo->mask);
    for (int e; (e = memo->table[at]) >= 0; at = (at + 1) & memo->mask) {
        if (memcmp(memo->keys + (size_t)e * width, key, (size_t)width * sizeof(double)) == 0) {
            memo->set(model, data, memo->states + (size_t)e * memo->size, memo->sig);
            step(model, data);
            memo->hits++;
            return;
        }
    }
    if (flags) *flags |= COTWIN_DSBL_SENSOR;  /* the last step's sensors are computed below, after the state is kept */
    for (int k = 0; k < n - 1; k++) step(model, data);
    if (memo->count < memo->capacity) {
        int e = memo->count++;
        memcpy(memo->keys + (size_t)e * width, key, (size_t)width * sizeof(double));
        memo->get(model, data, memo->states + (size_t)e * memo->size, memo->sig);
        memo->table[at] = e;
    }
    memo->misses++;
    if (flags) *flags &= ~COTWIN_DSBL_SENSOR;
    step(model, data);
}
"""

SOURCE = SOURCE.replace("@SENSOR@", str(SENSOR))
STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # as cotwin.pmodel.simulator saves and restores forks
BUDGET = 8 << 20  # bytes a memo's stretches take at most (its table and a scratch row besides)
MAX_STRETCHES = 4096


class _Memo(ctypes.Structure):
    _fields_ = [("get", ctypes.c_void_p), ("set", ctypes.c_void_p), ("sig", ctypes.c_int), ("size", ctypes.c_int),
                ("capacity", ctypes.c_int), ("count", ctypes.c_int), ("mask", ctypes.c_int),
                ("keys", ctypes.c_void_p), ("states", ctypes.c_void_p), ("table", ctypes.c_void_p),
                ("scratch", ctypes.c_void_p), ("hits", ctypes.c_longlong), ("misses", ctypes.c_longlong)]


def model_digest(model: mujoco.MjModel) -> int | None:
    """A digest of everything in `model` that its steps read (its buffer of arrays and its options), or None."""
    functions = model_functions()
    return functions[1](model._address) if functions is not None else None


def remembers(model: mujoco.MjModel, digest: int | None = None) -> bool:
    """Whether a memo can stand for `model`'s steps: MuJoCo keeps no state of its own outside the integration
    state (no sleeping bodies, no plugins) and the model's digest can be made (`digest`: made already)."""
    sleep = getattr(mujoco.mjtEnableBit, "mjENBL_SLEEP", None)
    if sleep is not None and model.opt.enableflags & int(sleep):
        return False
    return model.nplugin == 0 and (digest if digest is not None else model_digest(model)) is not None


class StepMemo:
    """The held stretches of one simulator's model (see the module doc); `address` is what the C takes."""

    def __init__(self, model: mujoco.MjModel, budget: int = BUDGET):
        functions = address("mj_getState"), address("mj_setState")
        if None in functions:
            raise ValueError("MuJoCo's library was not found beside the mujoco module")
        self.digest = model_digest(model)
        if not remembers(model, self.digest):
            raise ValueError("this model's steps depend on more than its integration state, or its digest cannot be made")
        size = mujoco.mj_stateSize(model, STATE)
        capacity = max(1, min(MAX_STRETCHES, budget // ((2 * size + 1) * 8)))
        slots = 1 << (2 * capacity - 1).bit_length()  # at least twice the entries: the table is never full
        self.keys = np.zeros((capacity, size + 1))
        self.states = np.zeros((capacity, size))
        self.table = np.full(slots, -1, dtype=np.int32)
        self.scratch = np.zeros(size + 1)
        self._memo = _Memo(functions[0], functions[1], int(STATE), size, capacity, 0, slots - 1,
                           self.keys.ctypes.data, self.states.ctypes.data, self.table.ctypes.data,
                           self.scratch.ctypes.data, 0, 0)
        self.address = ctypes.addressof(self._memo)
        self.capacity = capacity

    @property
    def hits(self) -> int:
        """Stretches taken from the memo."""
        return self._memo.hits

    @property
    def misses(self) -> int:
        """Stretches of two steps or more stepped in full."""
        return self._memo.misses

    @property
    def stretches(self) -> int:
        """Stretches kept."""
        return self._memo.count

    @property
    def full(self) -> int:
        """Bytes its stretches take once it has kept `capacity` of them (its arrays of states: made untouched, resident
        only as stretches are kept; the table and the scratch row are touched when it is made)."""
        return self.keys.nbytes + self.states.nbytes

    def clear(self) -> None:
        """Forget every stretch (the model changed)."""
        self.table.fill(-1)
        self._memo.count = 0

    def check(self, model: mujoco.MjModel) -> None:
        """Forget every stretch if `model`'s numbers changed since they were kept (before a native stretch); while
        the model's options let MuJoCo keep state outside the integration state (its bodies may now sleep), keep
        none and take none: every stretch is stepped in full."""
        digest = model_digest(model)
        if digest != self.digest:
            self.clear()
            self.digest = digest
            self._memo.capacity = self.capacity if remembers(model, digest) else 0
