"""Rows of a CSV as text in C, spelt exactly as CSVWriter spells them (issue 23).

CSVWriter writes a step's time rounded to 12 digits and each value as Python's repr spells it (booleans
true/false). Formatting the native loop's thousands of rows through Python tuples cost more than the
physics; this function formats them in C with Python's own float-to-text function
(PyOS_double_to_string: repr's shortest round-trip digits, and round()'s correctly rounded digits),
passed by address, so the text is the one repr gives, byte for byte. None where it cannot be built here
(then CSVWriter formats the rows itself).
"""

from __future__ import annotations

import ctypes

import numpy as np

SOURCE = r"""
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <stddef.h>

typedef char *(*to_text)(double, char, int, int, int *);
typedef double (*to_double)(const char *, char **, void *);
typedef void (*release)(void *);

/* Appends `text` at out + *at if it fits in cap; returns 0 when out of room. */
static int put(char *out, size_t cap, size_t *at, const char *text, size_t n) {
    if (*at + n > cap) return 0;
    memcpy(out + *at, text, n);
    *at += n;
    return 1;
}

static int real(char *out, size_t cap, size_t *at, double value, to_text text, release free_text) {
    char *s = text(value, 'r', 0, 2 /* Py_DTSF_ADD_DOT_0 */, NULL);
    if (!s) return 0;
    int ok = put(out, cap, at, s, strlen(s));
    free_text(s);
    return ok;
}

/* A column's last real and its text: a value the row before had (most columns hold still) is copied. */
typedef struct { unsigned long long bits; int n; char text[40]; } memo;

static int real_memo(char *out, size_t cap, size_t *at, double value, memo *m, to_text text, release free_text) {
    unsigned long long bits;
    memcpy(&bits, &value, sizeof bits);
    if (m->n > 0 && m->bits == bits) return put(out, cap, at, m->text, (size_t)m->n);
    char *s = text(value, 'r', 0, 2 /* Py_DTSF_ADD_DOT_0 */, NULL);
    if (!s) return 0;
    size_t n = strlen(s);
    int ok = put(out, cap, at, s, n);
    if (n < sizeof m->text) { memcpy(m->text, s, n); m->n = (int)n; m->bits = bits; } else m->n = 0;
    free_text(s);
    return ok;
}

/* round(t, 12) as repr spells it, without Python's text functions where that is exact: p = t * 1e12 is
   within 0.125 of the exact product below 2^50, so when p is within 0.25 of an integer N, N is the
   correctly rounded 12-digit value; N / 1e12 is then the double round() returns (one correctly rounded
   division), and when N has at most 15 digits its decimal, trailing zeros dropped, is repr's shortest
   text (two decimals of 15 digits or fewer never round to one double). Returns the length, 0 otherwise. */
static int time_text(double t, char *buffer) {
    double p = t * 1e12;
    if (!(p >= 1e8 && p < 1e15)) return 0;  /* 1e-4 <= t < 1000: repr's fixed notation, at most 15 digits */
    double n = floor(p + 0.5);
    if (fabs(p - n) > 0.25) return 0;
    long long whole = (long long)n;
    long long units = whole / 1000000000000LL, fraction = whole % 1000000000000LL;
    int at = snprintf(buffer, 40, "%lld.%012lld", units, fraction);
    while (at > 0 && buffer[at - 1] == '0' && buffer[at - 2] != '.') at--;
    buffer[at] = 0;
    return at;
}

/* rows: nrows x stride doubles; the columns' slots and kinds ('r', 'i', 'b'); times: each row's time.
   Returns the bytes written, or (size_t)-1 when cap was too small or text failed. */
size_t cotwin_rows_text(const double *rows, int nrows, int stride, const int *slots, const char *kinds, int ncols,
                        const double *times, char *out, size_t cap, to_text text, to_double number, release free_text,
                        void *memory) {
    size_t at = 0;
    char buffer[48];
    memo *memos = (memo *)memory;  /* one per column, zeroed by the caller */
    for (int r = 0; r < nrows; r++) {
        int n = time_text(times[r], buffer);
        if (n > 0) {
            if (!put(out, cap, &at, buffer, (size_t)n)) return (size_t)-1;
        } else {
            char *rounded = text(times[r], 'f', 12, 0, NULL);  /* round(t, 12): correctly rounded, read back */
            if (!rounded) return (size_t)-1;
            double t = number(rounded, NULL, NULL);
            free_text(rounded);
            if (!real(out, cap, &at, t, text, free_text)) return (size_t)-1;
        }
        const double *row = rows + (size_t)r * stride;
        for (int c = 0; c < ncols; c++) {
            double v = row[slots[c]];
            if (!put(out, cap, &at, ",", 1)) return (size_t)-1;
            if (kinds[c] == 'b') {
                if (!(v != 0.0 ? put(out, cap, &at, "true", 4) : put(out, cap, &at, "false", 5))) return (size_t)-1;
            } else if (kinds[c] == 'i') {
                int n = snprintf(buffer, sizeof buffer, "%lld", (long long)v);
                if (!put(out, cap, &at, buffer, (size_t)n)) return (size_t)-1;
            } else if (!real_memo(out, cap, &at, v, &memos[c], text, free_text)) {
                return (size_t)-1;
            }
        }
        if (!put(out, cap, &at, "\n", 1)) return (size_t)-1;
    }
    return at;
}
"""

_FN: object = None
MEMO = 64  # bytes of a column's memo (the C struct's 8 + 4 + 40, padded) with room to spare


def _function():
    global _FN
    if _FN is None:
        from .native import compile_library

        try:
            lib = compile_library(SOURCE, "rowtext")
        except ValueError:
            _FN = False
            return None
        fn = lib.cotwin_rows_text
        fn.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int,
                       ctypes.c_void_p, ctypes.c_char_p, ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p,
                       ctypes.c_void_p, ctypes.c_void_p]
        fn.restype = ctypes.c_size_t
        api = ctypes.pythonapi
        addresses = [ctypes.cast(getattr(api, name), ctypes.c_void_p).value
                     for name in ("PyOS_double_to_string", "PyOS_string_to_double", "PyMem_Free")]
        _FN = (fn, addresses)
    return _FN or None


def rows_text(rows: np.ndarray, slots: list[int], kinds: str, times: list[float]) -> str | None:
    """The rows (doubles, the columns at `slots` of kinds 'r'/'i'/'b') as CSV lines after each row's time;
    None where the C function cannot be built here."""
    function = _function()
    if function is None:
        return None
    fn, (text, number, release) = function
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    columns = np.array(slots, dtype=np.intc)
    at = np.array(times, dtype=np.float64)
    cap = len(rows) * (len(slots) + 1) * 26 + 64  # 24 characters at most per number, a comma, a newline
    out = ctypes.create_string_buffer(cap)
    memos = ctypes.create_string_buffer(MEMO * max(1, len(slots)))  # zeroed
    n = fn(rows.ctypes.data, len(rows), rows.shape[1] if rows.ndim == 2 else 0, columns.ctypes.data,
           kinds.encode("ascii"), len(slots), at.ctypes.data, out, cap, text, number, release, memos)
    if n == ctypes.c_size_t(-1).value:
        return None
    return out.raw[:n].decode("ascii")
