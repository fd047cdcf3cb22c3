"""Rows of a CSV as text in C, spelt exactly as CSVWriter spells them (issue 23).

CSVWriter writes a step's time rounded to 12 digits and each value as Python's repr spells it (booleans
true/false). Formatting the native loop's thousands of rows through Python tuples cost more than the
physics; this function formats them in C: a real by Grisu3 (the shortest digits that read back as the
double, the closest of them, laid out as repr lays them out) where Grisu3 is certain, else by Python's own
float-to-text function (PyOS_double_to_string, repr's), passed by address; a time by exact integer
arithmetic where that is exact, else as round() and repr make it. So the text is the one repr gives, byte
for byte (tests/test_native.py checks every power of two and its neighbours, and random doubles). A
column's text is reused while its value holds still. None where it cannot be built here (then CSVWriter
formats the rows itself).
"""

from __future__ import annotations

import ctypes
import threading

import numpy as np

_TEMPLATE = r"""
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <stddef.h>

typedef char *(*to_text)(double, char, int, int, int *);
typedef double (*to_double)(const char *, char **, void *);
typedef void (*release)(void *);
/* Python's functions the text falls back on, called holding the GIL (the rows are spelt without it, so that
   other threads run meanwhile): PyOS_double_to_string, PyOS_string_to_double, PyMem_Free,
   PyGILState_Ensure, PyGILState_Release, PyErr_Clear (a failure reported as such, no exception left set). */
typedef struct { to_text text; to_double number; release free_text; int (*take)(void); void (*give)(int);
                 void (*clear)(void); } python;

/* Appends `text` at out + *at if it fits in cap; returns 0 when out of room. */
static int put(char *out, size_t cap, size_t *at, const char *text, size_t n) {
    if (*at + n > cap) return 0;
    memcpy(out + *at, text, n);
    *at += n;
    return 1;
}

/* value's decimal digits, at least `width` (zeros before), at out; returns how many. */
static int decimal(char *out, unsigned long long value, int width) {
    char digits[24];
    int n = 0;
    do { digits[n++] = (char)('0' + value % 10); value /= 10; } while (value);
    while (n < width) digits[n++] = '0';
    for (int i = 0; i < n; i++) out[i] = digits[n - 1 - i];
    return n;
}

@GRISU@

static int real(char *out, size_t cap, size_t *at, double value, const python *py) {
    char fast[40];
    int n = shortest(value, fast);
    if (n > 0) return put(out, cap, at, fast, (size_t)n);
    int gil = py->take();
    char *s = py->text(value, 'r', 0, 2 /* Py_DTSF_ADD_DOT_0 */, NULL);
    int ok = s && put(out, cap, at, s, strlen(s));
    if (s) py->free_text(s); else py->clear();
    py->give(gil);
    return ok;
}

/* A column's last real and its text: a value the row before had (most columns hold still) is copied. */
typedef struct { unsigned long long bits; int n; char text[40]; } memo;

static int real_memo(char *out, size_t cap, size_t *at, double value, memo *m, const python *py) {
    unsigned long long bits;
    memcpy(&bits, &value, sizeof bits);
    if (m->n > 0 && m->bits == bits) return put(out, cap, at, m->text, (size_t)m->n);
    int k = shortest(value, m->text);
    if (k > 0) { m->n = k; m->bits = bits; return put(out, cap, at, m->text, (size_t)k); }
    int gil = py->take();
    char *s = py->text(value, 'r', 0, 2 /* Py_DTSF_ADD_DOT_0 */, NULL);
    int ok = 0;
    if (s) {
        size_t n = strlen(s);
        ok = put(out, cap, at, s, n);
        if (n < sizeof m->text) { memcpy(m->text, s, n); m->n = (int)n; m->bits = bits; } else m->n = 0;
        py->free_text(s);
    } else {
        py->clear();
    }
    py->give(gil);
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
    int at = decimal(buffer, (unsigned long long)units, 1);  /* "%lld.%012lld" without snprintf's cost */
    buffer[at++] = '.';
    at += decimal(buffer + at, (unsigned long long)fraction, 12);
    while (at > 0 && buffer[at - 1] == '0' && buffer[at - 2] != '.') at--;
    buffer[at] = 0;
    return at;
}

/* rows: nrows x stride doubles; the columns' slots and kinds ('r', 'i', 'b'); times: each row's time.
   Returns the bytes written, or (size_t)-1 when cap was too small or text failed. */
size_t cotwin_rows_text(const double *rows, int nrows, int stride, const int *slots, const char *kinds, int ncols,
                        const double *times, double origin, long long first, double step, char *out, size_t cap,
                        const python *py, void *memory) {
    size_t at = 0;
    char buffer[48];
    memo *memos = (memo *)memory;  /* one per column, zeroed by the caller */
    for (int r = 0; r < nrows; r++) {
        /* the row's time: given, or origin + (first + r) * step as the execution counts it */
        double time = times ? times[r] : origin + (double)(first + r) * step;
        int n = time_text(time, buffer);
        if (n > 0) {
            if (!put(out, cap, &at, buffer, (size_t)n)) return (size_t)-1;
        } else {
            int gil = py->take();
            char *rounded = py->text(time, 'f', 12, 0, NULL);  /* round(t, 12): correctly rounded, read back */
            double t = rounded ? py->number(rounded, NULL, NULL) : 0.0;
            if (rounded) py->free_text(rounded); else py->clear();
            py->give(gil);
            if (!rounded || !real(out, cap, &at, t, py)) return (size_t)-1;
        }
        const double *row = rows + (size_t)r * stride;
        for (int c = 0; c < ncols; c++) {
            double v = row[slots[c]];
            if (!put(out, cap, &at, ",", 1)) return (size_t)-1;
            if (kinds[c] == 'b') {
                if (!(v != 0.0 ? put(out, cap, &at, "true", 4) : put(out, cap, &at, "false", 5))) return (size_t)-1;
            } else if (kinds[c] == 'i') {
                memo *m = &memos[c];
                unsigned long long bits;
                memcpy(&bits, &v, sizeof bits);
                if (!(m->n > 0 && m->bits == bits)) {
                    m->n = snprintf(m->text, sizeof m->text, "%lld", (long long)v);
                    m->bits = bits;
                }
                if (!put(out, cap, &at, m->text, (size_t)m->n)) return (size_t)-1;
            } else if (!real_memo(out, cap, &at, v, &memos[c], py)) {
                return (size_t)-1;
            }
        }
        if (!put(out, cap, &at, "\n", 1)) return (size_t)-1;
    }
    return at;
}
"""

_GRISU = r"""
/* repr's text of a double without Python, where that is certain: Grisu3 (Loitsch, "Printing floating-point
   numbers quickly and accurately with integers", PLDI 2010) finds the shortest digits that read back as the
   double and the closest such, or says it cannot be sure (about 0.5% of doubles), and the text is laid
   out as repr lays it out. Returns the length, 0 when the caller must ask Python. */
typedef struct { uint64_t f; int e; } diy;

static const uint64_t POWER_F[] = {@POWER_F@};
static const int16_t POWER_E[] = {@POWER_E@};
#define POWER_KMIN (@KMIN@)
#define POWER_COUNT (@COUNT@)

static diy diy_mul(diy a, diy b) {
    unsigned __int128 p = (unsigned __int128)a.f * b.f;
    uint64_t high = (uint64_t)(p >> 64);
    if ((uint64_t)p & (1ULL << 63)) high++;  /* rounded half up at bit 64 */
    diy r = {high, a.e + b.e + 64};
    return r;
}

static diy diy_normalized(diy a) {
    int shift = __builtin_clzll(a.f);
    a.f <<= shift;
    a.e -= shift;
    return a;
}

static int round_weed(char *buffer, int length, uint64_t distance_too_high_w, uint64_t unsafe_interval, uint64_t rest,
                      uint64_t ten_kappa, uint64_t unit) {
    uint64_t small_distance = distance_too_high_w - unit;
    uint64_t big_distance = distance_too_high_w + unit;
    while (rest < small_distance && unsafe_interval - rest >= ten_kappa &&
           (rest + ten_kappa < small_distance || small_distance - rest >= rest + ten_kappa - small_distance)) {
        buffer[length - 1]--;
        rest += ten_kappa;
    }
    if (rest < big_distance && unsafe_interval - rest >= ten_kappa &&
        (rest + ten_kappa < big_distance || big_distance - rest > rest + ten_kappa - big_distance)) return 0;
    return (2 * unit <= rest) && (rest <= unsafe_interval - 4 * unit);
}

static int digit_gen(diy low, diy w, diy high, char *buffer, int *length, int *kappa) {
    uint64_t unit = 1;
    diy too_low = {low.f - unit, low.e}, too_high = {high.f + unit, high.e};
    uint64_t unsafe_interval = too_high.f - too_low.f;
    int shift = -w.e;
    uint64_t one = 1ULL << shift;
    uint32_t integrals = (uint32_t)(too_high.f >> shift);
    uint64_t fractionals = too_high.f & (one - 1);
    uint32_t divisor = 1;
    int digits = 1;
    while (digits < 10 && (uint64_t)divisor * 10 <= integrals) { divisor *= 10; digits++; }
    if (integrals == 0) { divisor = 1; digits = 0; }
    *kappa = digits;
    *length = 0;
    while (*kappa > 0) {
        uint32_t digit = integrals / divisor;
        buffer[(*length)++] = (char)('0' + digit);
        integrals %= divisor;
        (*kappa)--;
        uint64_t rest = ((uint64_t)integrals << shift) + fractionals;
        if (rest < unsafe_interval)
            return round_weed(buffer, *length, too_high.f - w.f, unsafe_interval, rest, (uint64_t)divisor << shift, unit);
        divisor /= 10;
    }
    for (;;) {
        fractionals *= 10;
        unit *= 10;
        unsafe_interval *= 10;
        buffer[(*length)++] = (char)('0' + (int)(fractionals >> shift));
        fractionals &= one - 1;
        (*kappa)--;
        if (fractionals < unsafe_interval)
            return round_weed(buffer, *length, (too_high.f - w.f) * unit, unsafe_interval, fractionals, one, unit);
        if (*length >= 18) return 0;
    }
}

static int shortest(double value, char *out) {
    uint64_t bits;
    memcpy(&bits, &value, sizeof bits);
    int negative = (int)(bits >> 63);
    int biased = (int)((bits >> 52) & 0x7FF);
    uint64_t fraction = bits & ((1ULL << 52) - 1);
    if (biased == 0x7FF || (biased == 0 && fraction == 0)) return 0;  /* inf, nan, zeros: Python says */
    uint64_t f = biased ? fraction | (1ULL << 52) : fraction;
    int e = biased ? biased - 1075 : -1074;
    diy w = diy_normalized((diy){f, e});
    diy plus = diy_normalized((diy){(f << 1) + 1, e - 1});
    diy minus = (fraction == 0 && biased > 1) ? (diy){(f << 2) - 1, e - 2} : (diy){(f << 1) - 1, e - 1};
    minus.f <<= minus.e - plus.e;
    minus.e = plus.e;
    /* 10^K with -60 <= its exponent + w.e + 64 <= -32 */
    int K = (int)ceil((-60 - (w.e + 64) + 63) * 0.30102999566398114);
    for (int tries = 0; tries < 4; tries++) {
        int k = K - POWER_KMIN;
        if (k < 0 || k >= POWER_COUNT) return 0;
        int sum = POWER_E[k] + w.e + 64;
        if (sum < -60) K++; else if (sum > -32) K--; else break;
    }
    int k = K - POWER_KMIN;
    if (k < 0 || k >= POWER_COUNT) return 0;
    int sum = POWER_E[k] + w.e + 64;
    if (sum < -60 || sum > -32) return 0;
    diy c = {POWER_F[k], POWER_E[k]};
    char digits[24];
    int length, kappa;
    if (!digit_gen(diy_mul(minus, c), diy_mul(w, c), diy_mul(plus, c), digits, &length, &kappa)) return 0;
    while (length > 1 && digits[length - 1] == '0') { length--; kappa++; }
    if (length < 1 || digits[0] == '0') return 0;
    int point = length + kappa - K;  /* value = 0.d1d2...dn x 10^point */
    int at = 0;
    if (negative) out[at++] = '-';
    if (point <= -4 || point > 16) {  /* repr's exponent notation: d.ddde-05, de+16 */
        out[at++] = digits[0];
        if (length > 1) { out[at++] = '.'; memcpy(out + at, digits + 1, (size_t)(length - 1)); at += length - 1; }
        int x = point - 1;
        out[at++] = 'e';
        out[at++] = x < 0 ? '-' : '+';
        at += decimal(out + at, (unsigned long long)(x < 0 ? -x : x), 2);  /* "e%c%02d" without snprintf */
    } else if (point <= 0) {
        out[at++] = '0'; out[at++] = '.';
        for (int z = 0; z < -point; z++) out[at++] = '0';
        memcpy(out + at, digits, (size_t)length); at += length;
    } else if (point >= length) {
        memcpy(out + at, digits, (size_t)length); at += length;
        for (int z = 0; z < point - length; z++) out[at++] = '0';
        out[at++] = '.'; out[at++] = '0';
    } else {
        memcpy(out + at, digits, (size_t)point); at += point;
        out[at++] = '.';
        memcpy(out + at, digits + point, (size_t)(length - point)); at += length - point;
    }
    out[at] = 0;
    return at;
}
"""


def _powers(kmin: int = -348, kmax: int = 341) -> tuple[list[int], list[int]]:
    """10^K for K in [kmin, kmax] as 64-bit significands f (bit 63 set) and exponents e, f x 2^e rounded to
    the nearest: exact integer arithmetic, so the table is the same on every machine."""
    fs, es = [], []
    for k in range(kmin, kmax + 1):
        if k >= 0:
            n, d = 10 ** k, 1
        else:
            n, d = 1, 10 ** -k
        e = (n.bit_length() - d.bit_length()) - 64  # f = n / d / 2^e, adjusted into [2^63, 2^64)
        while True:
            num, den = (n, d << e) if e >= 0 else (n << -e, d)
            f, r = divmod(num, den)
            if f >= 1 << 64:
                e += 1
                continue
            if f < 1 << 63:
                e -= 1
                continue
            break
        if 2 * r > den or (2 * r == den and f & 1):
            f += 1
            if f == 1 << 64:
                f, e = 1 << 63, e + 1
        fs.append(f)
        es.append(e)
    return fs, es


def _source() -> str:
    fs, es = _powers()
    grisu = (_GRISU.replace("@POWER_F@", ", ".join(f"{f}ULL" for f in fs)).replace("@POWER_E@", ", ".join(map(str, es)))
             .replace("@KMIN@", "-348").replace("@COUNT@", str(len(fs))))
    return _TEMPLATE.replace("@GRISU@", grisu)


SOURCE = _source()

_FN: object = None
MEMO = 64  # bytes of a column's memo (the C struct's 8 + 4 + 40, padded) with room to spare


def _function():
    global _FN
    if _FN is None:
        from ..cbuild import compile_library

        try:
            lib = compile_library(SOURCE, "rowtext", keep_gil=False)  # other threads run while rows are spelt
        except ValueError:
            _FN = False
            return None
        fn = lib.cotwin_rows_text
        fn.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int,
                       ctypes.c_void_p, ctypes.c_double, ctypes.c_longlong, ctypes.c_double, ctypes.c_char_p,
                       ctypes.c_size_t, ctypes.c_void_p, ctypes.c_void_p]
        fn.restype = ctypes.c_size_t
        api = ctypes.pythonapi  # the C struct `python`: the functions it calls holding the GIL
        python = (ctypes.c_void_p * 6)(*(ctypes.cast(getattr(api, name), ctypes.c_void_p).value for name in (
            "PyOS_double_to_string", "PyOS_string_to_double", "PyMem_Free", "PyGILState_Ensure", "PyGILState_Release",
            "PyErr_Clear")))
        _FN = (fn, python)
    return _FN or None


def available() -> bool:
    """Whether rows_text can make text here (its C function built)."""
    return _function() is not None


def rows_text(rows: np.ndarray, slots: list[int], kinds: str, times: list[float] | None = None,
              counted: tuple[float, int, float] | None = None, encoded: bool = False) -> str | bytes | None:
    """The rows (doubles, the columns at `slots` of kinds 'r'/'i'/'b') as CSV lines after each row's time:
    `times`, or `counted` = (origin, n, step): row r's time is origin + (n + r) * step, as an execution counts
    its steps; ASCII bytes with `encoded` (what a file gets: no decoding and encoding again). None where the C
    function cannot be built here."""
    function = _function()
    if function is None:
        return None
    fn, python = function
    rows = np.ascontiguousarray(rows, dtype=np.float64)
    columns = np.array(slots, dtype=np.intc)
    at = np.array(times, dtype=np.float64) if times is not None else None
    origin, first, step = counted if counted is not None else (0.0, 0, 0.0)
    cap = len(rows) * (len(slots) + 1) * 26 + 64  # 24 characters at most per number, a comma, a newline
    out = _buffer(cap)
    memos = ctypes.create_string_buffer(MEMO * max(1, len(slots)))  # zeroed
    n = fn(rows.ctypes.data, len(rows), rows.shape[1] if rows.ndim == 2 else 0, columns.ctypes.data,
           kinds.encode("ascii"), len(slots), at.ctypes.data if at is not None else None, origin, first, step, out,
           cap, ctypes.addressof(python), memos)
    if n == ctypes.c_size_t(-1).value:
        return None
    text = ctypes.string_at(out, n)
    return text if encoded else text.decode("ascii")


_LOCAL = threading.local()


def _buffer(size: int):
    """A text buffer of at least `size` bytes, kept per thread (not zeroed: the function says how much it wrote)."""
    buffer = getattr(_LOCAL, "buffer", None)
    if buffer is None or len(buffer) < size:
        buffer = _LOCAL.buffer = ctypes.create_string_buffer(max(size, 1 << 16))
    return buffer
