"""The endpoint's control-period loop in C: a move's set-points and MuJoCo's steps between them, in one call.

`SimulatedEndpoint.advance` refreshes the servos' set-points every CONTROL_PERIOD (2 ms) along the move
in flight, stepping MuJoCo between refreshes; in Python that loop cost about as much as the physics it
drives at steps of 0.01 and 0.1 s (issue 23). This module compiles (once per machine: cotwin.cbuild) a C function doing the same loop:
the move's fraction (quintic or trapezoid, the same expressions in the same order as
cotwin.mapping.motion, with floating-point contraction off so that every value is the same double), each
joint's set-point start + s * move clipped to its servo's range, MuJoCo's own `mj_step` (its address
taken from the library the `mujoco` module loaded) n times, and the simulator's check that the state
stays finite after each call. So a run gives the same trajectory, bit for bit, as the Python loop
(tests/test_fused.py and the byte-identical CSVs). Where it does not apply (no C compiler, a simulator
with ray sensors or obstacle contacts to check between steps, a set-point that is not a finite number) the
Python loop runs, as before.
"""

from __future__ import annotations

import ctypes
import subprocess

from ..pmodel.mujoco_c import address
from ..pmodel.sensing import SENSOR

SOURCE = r"""
#include <math.h>
#define COTWIN_DSBL_SENSOR @SENSOR@  /* mjDSBL_SENSOR */
#include <stddef.h>

typedef void (*step_fn)(const void *, void *);

static double trapezoid_duration(double a, double v, double distance) {
    if (distance <= 0) return 0.0;
    if (distance >= v * v / a) return distance / v + v / a;
    return 2.0 * sqrt(distance / a);
}

static double travelled(double a, double v, double distance, double elapsed) {
    double total = trapezoid_duration(a, v, distance);
    if (elapsed >= total) return distance;
    if (elapsed <= 0) return 0.0;
    double root = sqrt(a * distance);
    double peak = root < v ? root : v;  /* Python's min(v, root): v unless root < v */
    double ramp = peak / a;
    if (elapsed <= ramp) return 0.5 * a * elapsed * elapsed;
    if (elapsed <= total - ramp) return 0.5 * peak * ramp + peak * (elapsed - ramp);
    double left = total - elapsed;
    return distance - 0.5 * a * left * left;
}

static double fraction(const double *move, double t) {
    /* move: t0, duration, trapezoid (0/1), a, v, distance */
    double elapsed = t - move[0];
    if (move[1] <= 0 || elapsed >= move[1]) return 1.0;
    if (elapsed <= 0) return 0.0;
    if (move[2] != 0.0) return travelled(move[3], move[4], move[5], elapsed) / move[5];
    double tau = elapsed / move[1];
    return pow(tau, 3.0) * (10 - 15 * tau + 6 * tau * tau);
}

/* Returns 0 when all `steps` are done; 1 when a set-point is not finite (nothing written in that period:
   the caller's Python loop goes on from there and says why); 2 when the state became non-finite. `done`
   counts the physics steps made; `held` is set once the set-point stays at the move's end; `time` is the
   simulation time, advanced as MuJoCo advances it (the caller checks that they agree). */
static int cotwin_control(step_fn step, const void *model, void *data, double *time, double timestep,
                          double opt_timestep, int steps, int period, const double *move, int joints, const int *index,
                          const double *start, const double *delta, const double *low, const double *high,
                          double *ctrl, const double *qpos, int nq, int *held, int *done, int *flags) {
    while (steps > 0) {
        int n = period < steps ? period : steps;
        if (!*held) {
            double ahead = *time + n * timestep;
            double s = fraction(move, ahead);
            for (int k = 0; k < joints; k++) {
                double value = start[k] + s * delta[k];
                if (!(value - value == 0.0)) return 1;
            }
            for (int k = 0; k < joints; k++) {
                double value = start[k] + s * delta[k];
                ctrl[index[k]] = value < low[k] ? low[k] : value > high[k] ? high[k] : value;
            }
            if (ahead >= move[0] + move[1]) *held = 1;
        }
        if (*held) n = steps;
        for (int k = 0; k < n; k++) {
            if (flags && k == steps - 1) *flags &= ~COTWIN_DSBL_SENSOR;  /* the stretch's last step */
            step(model, data);
            *time += opt_timestep;  /* as mj_step advances data->time (Euler and implicit integrators) */
        }
        *done += n;
        steps -= n;
        double sum = 0.0;
        for (int k = 0; k < nq; k++) sum += qpos[k] * qpos[k];
        if (!(sum - sum == 0.0)) return 2;
    }
    return 0;
}

int cotwin_advance(step_fn step, const void *model, void *data, double *time, double timestep, double opt_timestep,
                   int steps, int period, const double *move, int joints, const int *index,
                   const double *start, const double *delta, const double *low, const double *high,
                   double *ctrl, const double *qpos, int nq, int *held, int *done, int *flags) {
    *done = 0;
    if (flags) *flags |= COTWIN_DSBL_SENSOR;  /* sensors in the last step only (cotwin.pmodel.sensing) */
    /* after status 1 or 2 the last step made may have had its sensors off: the caller raises, reading nothing */
    int status = cotwin_control(step, model, data, time, timestep, opt_timestep, steps, period, move, joints, index,
                                start, delta, low, high, ctrl, qpos, nq, held, done, flags);
    if (flags) *flags &= ~COTWIN_DSBL_SENSOR;
    return status;
}
"""

SOURCE = SOURCE.replace("@SENSOR@", str(SENSOR))

_LIB: object = None  # the loaded function, False when it cannot be built here, None before trying


def _build() -> ctypes.CDLL | None:
    from ..cbuild import compile_library

    try:
        return compile_library(SOURCE, "advance", keep_gil=False)
    except ValueError:
        return None


def _mj_step():
    """The address of MuJoCo's mj_step in the library the mujoco module loaded."""
    return address("mj_step")


def advance_function():
    """The C loop (a ctypes function with its argument types), or None where it cannot run here."""
    global _LIB
    if _LIB is None:
        try:
            lib, step = _build(), _mj_step()
        except (OSError, subprocess.SubprocessError):
            lib, step = None, None
        if lib is None or step is None:
            _LIB = False
        else:
            fn = lib.cotwin_advance
            P = ctypes.POINTER
            fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, P(ctypes.c_double), ctypes.c_double,
                           ctypes.c_double, ctypes.c_int, ctypes.c_int, P(ctypes.c_double), ctypes.c_int, P(ctypes.c_int),
                           P(ctypes.c_double), P(ctypes.c_double), P(ctypes.c_double), P(ctypes.c_double),
                           P(ctypes.c_double), P(ctypes.c_double), ctypes.c_int, P(ctypes.c_int), P(ctypes.c_int),
                           ctypes.c_void_p]
            fn.restype = ctypes.c_int
            _LIB = (fn, step)
    return _LIB or None
