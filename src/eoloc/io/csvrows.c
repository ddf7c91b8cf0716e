/* eoloc.io.csvrows: text rows from columns, with the GIL released.

   The CSV and GeoJSON writers (eoloc/io/csvfile.py, geojsonfile.py; the specs: rows.py) decide
   once per column how its cells are written; this module writes rows start .. start+n of every
   column, one row after the other, each cell with what surrounds it (a CSV separator, a JSON
   key), into one bytes object. What it does by hand, and why:

   - numbers rounded to a column's decimals exactly as numpy rounds them (x * 10^d, rint, the
     same IEEE operations) and written as orjson writes that rounded double (its shortest
     round-trip text): for |rint(x * 10^d)| <= 10^15 that text is the rounded integer's digits
     with the decimal point put back and trailing zeros dropped (no other decimal of 15 digits
     or fewer reads back as the same double), "1.0" style for whole values, the exponent form
     below 1e-5 ("2.5e-6") as orjson does. The writer checks each column's range first and
     sends any other column through orjson (tests: every cell against orjson, and against the
     pure-Python renderers byte for byte);
   - integers, coded text (an index into its pre-rendered names) and pre-rendered cells (a
     pyarrow string array's buffers) copied in.

   Nothing here allocates per cell or calls Python between rows, so two threads render two
   chunks at once (orjson and the pyarrow join it replaces hold, or need, the GIL for part of
   the work).

   render(start, n, columns) -> bytes; each column a tuple:
     (0, cell)                                      the same cell (bytes, separator included) on every row
     (1, values, decimals, whole, prefix, suffix, empty)
                                                    float64 numbers between prefix and suffix (bytes);
                                                    NaN: ``empty`` alone; whole: as integers
     (2, values, prefix, suffix)                    int64 numbers between prefix and suffix
     (3, codes, offsets, data)                      coded text: names[codes[row]] (int32 offsets)
     (4, offsets, data, validity, offset)           text cells of rows offset .. offset+n of a string
                                                    array (null: ",")
   Rows of kinds 1-3 are start .. start+n of the arrays; kind 4 is given its rows' array. */

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

enum { K_CONST = 0, K_FLOAT = 1, K_INT = 2, K_CODED = 3, K_CELLS = 4 };

#define MAX_BUFS 3

typedef struct {
    int kind;
    Py_buffer buf[MAX_BUFS];
    int nbuf;
    const char *text;   /* K_CONST: the cell; K_FLOAT: the empty cell */
    Py_ssize_t text_len;
    const char *prefix, *suffix;
    Py_ssize_t prefix_len, suffix_len;
    int decimals, whole;
    double scale;
    Py_ssize_t offset;  /* K_CELLS */
    Py_ssize_t nnames;  /* K_CODED */
    int code_size;      /* K_CODED: bytes per code */
    int has_validity;   /* K_CELLS */
} Col;

static const double POW10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

static const char DIGIT_PAIRS[201] =
    "00010203040506070809101112131415161718192021222324252627282930313233343536373839"
    "40414243444546474849505152535455565758596061626364656667686970717273747576777879"
    "8081828384858687888990919293949596979899";

static const uint64_t POW10U[20] = {1ULL,
                                   10ULL,
                                   100ULL,
                                   1000ULL,
                                   10000ULL,
                                   100000ULL,
                                   1000000ULL,
                                   10000000ULL,
                                   100000000ULL,
                                   1000000000ULL,
                                   10000000000ULL,
                                   100000000000ULL,
                                   1000000000000ULL,
                                   10000000000000ULL,
                                   100000000000000ULL,
                                   1000000000000000ULL,
                                   10000000000000000ULL,
                                   100000000000000000ULL,
                                   1000000000000000000ULL,
                                   10000000000000000000ULL};

/* How many decimal digits a has (at least 1). */
static inline int ndigits(uint64_t a) {
    int k = 1; /* a loop: the widths of a column's numbers vary little, so it is well predicted */
    while (k < 20 && a >= POW10U[k]) k++;
    return k;
}

/* Exactly len digits of a (leading zeros where it has fewer), ending just before end. */
static inline void digits_back(char *end, uint64_t a, int len) {
    while (len >= 2) {
        unsigned r = (unsigned)(a % 100);
        a /= 100;
        end -= 2;
        memcpy(end, DIGIT_PAIRS + 2 * r, 2);
        len -= 2;
    }
    if (len) *--end = (char)('0' + a % 10);
}

static inline char *put_u64(char *p, uint64_t a) {
    int k = ndigits(a);
    digits_back(p + k, a, k);
    return p + k;
}

static inline char *put_i64(char *p, int64_t x) {
    if (x < 0) {
        *p++ = '-';
        return put_u64(p, (uint64_t)0 - (uint64_t)x);
    }
    return put_u64(p, (uint64_t)x);
}

/* a / 10^d and its remainder; the usual decimals as constants (a multiplication, not a division). */
static inline uint64_t split(uint64_t a, int d, uint64_t *frac) {
    uint64_t q;
    switch (d) {
    case 4: q = a / 10000ULL; break;
    case 9: q = a / 1000000000ULL; break;
    default: q = a / POW10U[d];
    }
    *frac = a - q * POW10U[d];
    return q;
}

/* The text of rint(x * scale) / scale as orjson writes it; returns NULL when the rounded
   integer has more than 15 digits (the caller checked the range: a bug). */
static inline char *put_rounded(char *p, double x, double scale, int decimals) {
    double m = rint(x * scale);
    if (m == 0.0) {
        if (signbit(m)) *p++ = '-';
        memcpy(p, "0.0", 3);
        return p + 3;
    }
    *p = '-'; /* kept only for a negative number */
    p += m < 0;
    m = fabs(m);
    if (m > 1e15) return NULL;
    uint64_t frac, whole = split((uint64_t)m, decimals, &frac);
    if (frac == 0) { /* a whole number: orjson writes "12.0" */
        p = put_u64(p, whole);
        memcpy(p, ".0", 2);
        return p + 2;
    }
    int fd = decimals; /* the value is whole + frac * 10^-fd, frac without trailing zeros */
    while (frac % 10 == 0) {
        frac /= 10;
        fd--;
    }
    if (whole == 0) {
        int k = ndigits(frac);
        if (fd - k >= 5) { /* below 1e-5 (the first digit's power of ten -6 or less): "2.5e-6" */
            char dig[20] = {0};
            digits_back(dig + k, frac, k);
            *p++ = dig[0];
            if (k > 1) {
                *p++ = '.';
                memcpy(p, dig + 1, (size_t)(k - 1));
                p += k - 1;
            }
            *p++ = 'e';
            *p++ = '-';
            return put_u64(p, (uint64_t)(fd - k + 1));
        }
    }
    p = put_u64(p, whole);
    *p++ = '.';
    digits_back(p + fd, frac, fd);
    return p + fd;
}

static int get_buffer(PyObject *obj, Col *c, const char *what) {
    if (c->nbuf >= MAX_BUFS) {
        PyErr_SetString(PyExc_RuntimeError, "csvrows: too many buffers for one column");
        return -1;
    }
    if (PyObject_GetBuffer(obj, &c->buf[c->nbuf], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyErr_Format(PyExc_TypeError, "csvrows: %s is not a contiguous buffer", what);
        return -1;
    }
    c->nbuf++;
    return 0;
}

static void release(Col *cols, Py_ssize_t ncols) {
    for (Py_ssize_t j = 0; j < ncols; j++)
        for (int b = 0; b < cols[j].nbuf; b++) PyBuffer_Release(&cols[j].buf[b]);
}

static int text_of(PyObject *obj, const char **text, Py_ssize_t *len) {
    if (!PyBytes_Check(obj)) {
        PyErr_SetString(PyExc_TypeError, "csvrows: a prefix, suffix or cell text is bytes");
        return -1;
    }
    *text = PyBytes_AS_STRING(obj);
    *len = PyBytes_GET_SIZE(obj);
    return 0;
}

/* Short texts (separators, JSON keys) byte by byte: cheaper than a call to memcpy. */
static inline char *put_text(char *p, const char *text, Py_ssize_t len) {
    if (len > 16) {
        memcpy(p, text, (size_t)len);
        return p + len;
    }
    for (Py_ssize_t i = 0; i < len; i++) *p++ = text[i];
    return p;
}

static int is_format(const Py_buffer *b, const char *allowed, Py_ssize_t itemsize) {
    const char *f = b->format ? b->format : "B";
    if (*f == '<' || *f == '=' || *f == '@') f++;
    return f[0] && !f[1] && strchr(allowed, f[0]) && (itemsize == 0 || b->itemsize == itemsize);
}

/* Parses one column spec; returns the most bytes its n rows can take, or -1. */
static Py_ssize_t parse_col(PyObject *spec, Col *c, Py_ssize_t start, Py_ssize_t n) {
    if (!PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) < 2) {
        PyErr_SetString(PyExc_TypeError, "csvrows: a column is a tuple (kind, ...)");
        return -1;
    }
    Py_ssize_t size = PyTuple_GET_SIZE(spec);
    long kind = PyLong_AsLong(PyTuple_GET_ITEM(spec, 0));
    if (kind == -1 && PyErr_Occurred()) return -1;
    c->kind = (int)kind;
    static const Py_ssize_t sizes[5] = {2, 7, 4, 4, 5};
    if (kind < 0 || kind > 4 || size != sizes[kind]) {
        PyErr_Format(PyExc_ValueError, "csvrows: bad column spec of kind %ld", kind);
        return -1;
    }
    switch (kind) {
    case K_CONST: {
        if (!PyBytes_Check(PyTuple_GET_ITEM(spec, 1))) {
            PyErr_SetString(PyExc_TypeError, "csvrows: a constant cell is bytes");
            return -1;
        }
        c->text = PyBytes_AS_STRING(PyTuple_GET_ITEM(spec, 1));
        c->text_len = PyBytes_GET_SIZE(PyTuple_GET_ITEM(spec, 1));
        return c->text_len * n;
    }
    case K_FLOAT: {
        if (get_buffer(PyTuple_GET_ITEM(spec, 1), c, "a float column") < 0) return -1;
        if (!is_format(&c->buf[0], "d", 8)) {
            PyErr_SetString(PyExc_TypeError, "csvrows: a float column is float64");
            return -1;
        }
        long d = PyLong_AsLong(PyTuple_GET_ITEM(spec, 2));
        if (d == -1 && PyErr_Occurred()) return -1;
        if (d < 0 || d > 15) {
            PyErr_SetString(PyExc_ValueError, "csvrows: decimals are 0 to 15");
            return -1;
        }
        c->decimals = (int)d;
        c->scale = POW10[d];
        c->whole = PyObject_IsTrue(PyTuple_GET_ITEM(spec, 3));
        if (c->whole < 0 || text_of(PyTuple_GET_ITEM(spec, 4), &c->prefix, &c->prefix_len) < 0 ||
            text_of(PyTuple_GET_ITEM(spec, 5), &c->suffix, &c->suffix_len) < 0 ||
            text_of(PyTuple_GET_ITEM(spec, 6), &c->text, &c->text_len) < 0)
            return -1;
        if (c->buf[0].len / 8 < start + n) {
            PyErr_SetString(PyExc_IndexError, "csvrows: rows past the end of a float column");
            return -1;
        }
        Py_ssize_t cell = 32 + c->prefix_len + c->suffix_len;
        return (c->text_len > cell ? c->text_len : cell) * n;
    }
    case K_INT: {
        if (get_buffer(PyTuple_GET_ITEM(spec, 1), c, "an int column") < 0) return -1;
        if (!is_format(&c->buf[0], "lq", 8)) {
            PyErr_SetString(PyExc_TypeError, "csvrows: an int column is int64");
            return -1;
        }
        if (text_of(PyTuple_GET_ITEM(spec, 2), &c->prefix, &c->prefix_len) < 0 ||
            text_of(PyTuple_GET_ITEM(spec, 3), &c->suffix, &c->suffix_len) < 0)
            return -1;
        if (c->buf[0].len / 8 < start + n) {
            PyErr_SetString(PyExc_IndexError, "csvrows: rows past the end of an int column");
            return -1;
        }
        return (21 + c->prefix_len + c->suffix_len) * n;
    }
    case K_CODED: {
        if (get_buffer(PyTuple_GET_ITEM(spec, 1), c, "codes") < 0 || get_buffer(PyTuple_GET_ITEM(spec, 2), c, "offsets") < 0 ||
            get_buffer(PyTuple_GET_ITEM(spec, 3), c, "names") < 0)
            return -1;
        if (!is_format(&c->buf[0], "bhilq", 0) || !is_format(&c->buf[1], "i", 4)) {
            PyErr_SetString(PyExc_TypeError, "csvrows: codes are signed integers, offsets int32");
            return -1;
        }
        c->code_size = (int)c->buf[0].itemsize;
        c->nnames = c->buf[1].len / 4 - 1;
        if (c->buf[0].len / c->code_size < start + n || c->nnames < 0) {
            PyErr_SetString(PyExc_IndexError, "csvrows: rows past the end of the codes");
            return -1;
        }
        const int32_t *off = (const int32_t *)c->buf[1].buf;
        Py_ssize_t longest = 0;
        for (Py_ssize_t i = 0; i < c->nnames; i++) {
            if (off[i + 1] < off[i] || off[i] < 0 || off[i + 1] > c->buf[2].len) {
                PyErr_SetString(PyExc_ValueError, "csvrows: bad name offsets");
                return -1;
            }
            if (off[i + 1] - off[i] > longest) longest = off[i + 1] - off[i];
        }
        return longest * n;
    }
    default: { /* K_CELLS */
        if (get_buffer(PyTuple_GET_ITEM(spec, 1), c, "offsets") < 0 || get_buffer(PyTuple_GET_ITEM(spec, 2), c, "cells") < 0) return -1;
        c->has_validity = PyTuple_GET_ITEM(spec, 3) != Py_None;
        if (c->has_validity && get_buffer(PyTuple_GET_ITEM(spec, 3), c, "validity") < 0) return -1;
        c->offset = PyLong_AsSsize_t(PyTuple_GET_ITEM(spec, 4));
        if (c->offset == -1 && PyErr_Occurred()) return -1;
        if (c->offset < 0 || c->buf[0].len / 4 < c->offset + n + 1 ||
            (c->has_validity && c->buf[2].len * 8 < c->offset + n)) {
            PyErr_SetString(PyExc_IndexError, "csvrows: rows past the end of a cell array");
            return -1;
        }
        const int32_t *off = (const int32_t *)c->buf[0].buf;
        for (Py_ssize_t i = c->offset; i < c->offset + n; i++)
            if (off[i + 1] < off[i]) {
                PyErr_SetString(PyExc_ValueError, "csvrows: bad cell offsets");
                return -1;
            }
        if (n && (off[c->offset] < 0 || off[c->offset + n] > c->buf[1].len)) {
            PyErr_SetString(PyExc_ValueError, "csvrows: bad cell offsets");
            return -1;
        }
        return (n ? off[c->offset + n] - off[c->offset] : 0) + n;
    }
    }
}

static inline int64_t code_at(const Col *c, Py_ssize_t row) {
    const char *b = (const char *)c->buf[0].buf;
    switch (c->code_size) {
    case 1: return ((const int8_t *)b)[row];
    case 2: return ((const int16_t *)b)[row];
    case 4: return ((const int32_t *)b)[row];
    default: return ((const int64_t *)b)[row];
    }
}

/* Writes the rows; returns the end of the text, or NULL (*bad: what went wrong). */
static char *fill(char *p, const Col *cols, Py_ssize_t ncols, Py_ssize_t start, Py_ssize_t n, const char **bad) {
    for (Py_ssize_t i = 0; i < n; i++) {
        Py_ssize_t row = start + i;
        for (Py_ssize_t j = 0; j < ncols; j++) {
            const Col *c = &cols[j];
            switch (c->kind) {
            case K_CONST:
                p = put_text(p, c->text, c->text_len);
                break;
            case K_FLOAT: {
                double x = ((const double *)c->buf[0].buf)[row];
                if (isnan(x)) {
                    p = put_text(p, c->text, c->text_len);
                    break;
                }
                if (!isfinite(x)) {
                    *bad = "an infinity in a float column";
                    return NULL;
                }
                p = put_text(p, c->prefix, c->prefix_len);
                if (c->whole) {
                    double r = rint(x * c->scale) / c->scale;
                    if (!(fabs(r) < 9.2e18)) {
                        *bad = "a whole number past int64";
                        return NULL;
                    }
                    p = put_i64(p, (int64_t)r);
                } else {
                    p = put_rounded(p, x, c->scale, c->decimals);
                    if (!p) {
                        *bad = "a number with more than 15 digits";
                        return NULL;
                    }
                }
                p = put_text(p, c->suffix, c->suffix_len);
                break;
            }
            case K_INT:
                p = put_text(p, c->prefix, c->prefix_len);
                p = put_i64(p, ((const int64_t *)c->buf[0].buf)[row]);
                p = put_text(p, c->suffix, c->suffix_len);
                break;
            case K_CODED: {
                int64_t code = code_at(c, row);
                if (code < 0 || code >= c->nnames) {
                    *bad = "a code past its names";
                    return NULL;
                }
                const int32_t *off = (const int32_t *)c->buf[1].buf;
                p = put_text(p, (const char *)c->buf[2].buf + off[code], off[code + 1] - off[code]);
                break;
            }
            default: { /* K_CELLS */
                Py_ssize_t at = c->offset + i;
                if (c->has_validity && !((((const uint8_t *)c->buf[2].buf)[at >> 3] >> (at & 7)) & 1)) {
                    *p++ = ',';
                    break;
                }
                const int32_t *off = (const int32_t *)c->buf[0].buf;
                p = put_text(p, (const char *)c->buf[1].buf + off[at], off[at + 1] - off[at]);
            }
            }
        }
    }
    return p;
}

static PyObject *render(PyObject *self, PyObject *args) {
    (void)self;
    Py_ssize_t start, n;
    PyObject *specs;
    if (!PyArg_ParseTuple(args, "nnO!:render", &start, &n, &PyTuple_Type, &specs)) return NULL;
    if (start < 0 || n < 0) {
        PyErr_SetString(PyExc_ValueError, "csvrows: start and n are >= 0");
        return NULL;
    }
    Py_ssize_t ncols = PyTuple_GET_SIZE(specs);
    Col *cols = PyMem_Calloc((size_t)(ncols ? ncols : 1), sizeof(Col));
    if (!cols) return PyErr_NoMemory();
    Py_ssize_t bound = 0;
    for (Py_ssize_t j = 0; j < ncols; j++) {
        Py_ssize_t b = parse_col(PyTuple_GET_ITEM(specs, j), &cols[j], start, n);
        if (b < 0 || bound > PY_SSIZE_T_MAX - b) {
            if (b >= 0) PyErr_SetString(PyExc_OverflowError, "csvrows: too many bytes for one chunk");
            release(cols, j + 1);
            PyMem_Free(cols);
            return NULL;
        }
        bound += b;
    }
    PyObject *out = PyBytes_FromStringAndSize(NULL, bound);
    if (!out) {
        release(cols, ncols);
        PyMem_Free(cols);
        return NULL;
    }
    const char *bad = NULL;
    char *begin = PyBytes_AS_STRING(out), *end;
    Py_BEGIN_ALLOW_THREADS
    end = fill(begin, cols, ncols, start, n, &bad);
    Py_END_ALLOW_THREADS
    release(cols, ncols);
    PyMem_Free(cols);
    if (!end) {
        Py_DECREF(out);
        PyErr_Format(PyExc_ValueError, "csvrows: %s (the writer checks its columns first: a bug)", bad);
        return NULL;
    }
    if (_PyBytes_Resize(&out, end - begin) < 0) return NULL;
    return out;
}

static PyMethodDef methods[] = {
    {"render", render, METH_VARARGS,
     "render(start, n, columns) -> bytes: rows start .. start+n of the columns as CSV text (see the module)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "eoloc.io.csvrows",
                                    "CSV rows from columns, written with the GIL released (eoloc.io.csvfile).",
                                    -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit_csvrows(void) { return PyModule_Create(&module); }
