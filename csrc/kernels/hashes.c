/* Key and row hashes: evaluate's duplicate-key check and key join, the audit's duplicate rows. */
#include "kernels.h"

/* string_hashes(offsets int64[n+1], data uint8[], valid uint8[n] or None, out uint64[n], stems uint64[n] or None)
 * twin: hpe_cli.io.key_hash.string_hashes (numpy) */
#define P2 (P_FNV * P_FNV)
#define P3 (P2 * P_FNV)
#define P4 (P2 * P2)

static inline uint64_t span_hash(const uint8_t *d, int64_t s, int64_t e) {
    /* h = h * P + d[k] from the last byte to the first, four bytes a step: h * P^4 + d[k] P^3 + d[k-1] P^2 +
     * d[k-2] P + d[k-3] is the same value modulo 2^64, with one multiplication in the chain instead of four */
    uint64_t h = 0;
    int64_t k = e - 1;
    for (; k - 3 >= s; k -= 4) h = h * P4 + (d[k] * P3 + d[k - 1] * P2 + d[k - 2] * P_FNV + d[k - 3]);
    for (; k >= s; k--) h = h * P_FNV + d[k];
    h ^= (uint64_t)(e - s) * LEN_MULT;
    return mix64(h);
}

PyObject *k_string_hashes(PyObject *self, PyObject *args) {
    Py_buffer off, data, out, valid = {0}, stems = {0};
    PyObject *valid_o, *stems_o;
    if (!PyArg_ParseTuple(args, "y*y*Ow*O", &off, &data, &valid_o, &out, &stems_o)) return NULL;
    PyObject *ret = NULL;
    int have_valid = 0, have_stems = 0;
    Py_ssize_t n = out.len / 8;
    if (!optional_buffer(valid_o, &valid, PyBUF_SIMPLE, &have_valid) ||
        !optional_buffer(stems_o, &stems, PyBUF_WRITABLE, &have_stems))
        goto done;
    if (!need(&off, n + 1, 8, "offsets") || (have_valid && !need(&valid, n, 1, "valid")) ||
        (have_stems && !need(&stems, n, 8, "stems")))
        goto done;
    const int64_t *o = (const int64_t *)off.buf;
    const uint8_t *d = (const uint8_t *)data.buf;
    for (Py_ssize_t i = 0; i <= n; i++) {
        if (o[i] < 0 || o[i] > data.len || (i && o[i] < o[i - 1])) {
            PyErr_SetString(PyExc_ValueError, "offsets: expected increasing offsets within the data");
            goto done;
        }
    }
    uint64_t *h = (uint64_t *)out.buf, *hs = have_stems ? (uint64_t *)stems.buf : NULL;
    const uint8_t *v = have_valid ? (const uint8_t *)valid.buf : NULL;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t s = o[i], e = o[i + 1];
        if (v && !v[i]) {
            h[i] = NULL_HASH;
            if (hs) hs[i] = NULL_HASH;
            continue;
        }
        h[i] = span_hash(d, s, e);
        if (hs) {
            int64_t s0 = s, e0 = e;
            for (int64_t k = e - 1; k >= s; k--)
                if (d[k] == '/' || d[k] == '\\') {
                    s0 = k + 1;
                    break;
                }
            for (int64_t k = e - 1; k >= s0; k--)
                if (d[k] == '.') {
                    e0 = k;
                    break;
                }
            hs[i] = (s0 == s && e0 == e) ? h[i] : span_hash(d, s0, e0);
        }
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&off);
    PyBuffer_Release(&data);
    PyBuffer_Release(&out);
    if (have_valid) PyBuffer_Release(&valid);
    if (have_stems) PyBuffer_Release(&stems);
    return ret;
}

/* row_hash_add(h uint64[n] in place, words uint64[n] or float64[n], is_float)
 * h = ((h ^ w) * ROW_MULT) ^ (that >> 32); float64 values enter as their bits with -0.0 as 0.0 and every NaN as
 * one NaN.  twin: hpe_cli.pipelines.audit.duplicates.key_hashes (its loop over the columns) */
PyObject *k_row_hash_add(PyObject *self, PyObject *args) {
    Py_buffer h, w;
    int is_float;
    if (!PyArg_ParseTuple(args, "w*y*p", &h, &w, &is_float)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = h.len / 8;
    if (!need(&h, n, 8, "h") || !need(&w, n, 8, "words")) goto done;
    uint64_t *hp = (uint64_t *)h.buf;
    Py_BEGIN_ALLOW_THREADS
    if (is_float) {
        const double *x = (const double *)w.buf;
        for (Py_ssize_t i = 0; i < n; i++) {
            double y = x[i] + 0.0;
            uint64_t b;
            if (y != y)
                b = NAN_BITS;
            else
                memcpy(&b, &y, 8);
            uint64_t t = (hp[i] ^ b) * ROW_MULT;
            hp[i] = t ^ (t >> 32);
        }
    } else {
        const uint64_t *x = (const uint64_t *)w.buf;
        for (Py_ssize_t i = 0; i < n; i++) {
            uint64_t t = (hp[i] ^ x[i]) * ROW_MULT;
            hp[i] = t ^ (t >> 32);
        }
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&h);
    PyBuffer_Release(&w);
    return ret;
}

/* mix(h uint64[n] in place): SplitMix64's finaliser.  twin: hpe_cli.io.key_hash.mix */
PyObject *k_mix(PyObject *self, PyObject *args) {
    Py_buffer h;
    if (!PyArg_ParseTuple(args, "w*", &h)) return NULL;
    Py_ssize_t n = h.len / 8;
    if (!need(&h, n, 8, "h")) {
        PyBuffer_Release(&h);
        return NULL;
    }
    uint64_t *hp = (uint64_t *)h.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) hp[i] = mix64(hp[i]);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&h);
    Py_RETURN_NONE;
}

/* split_top_bit(h uint64[n], low uint64[n], high uint64[n]) -> number of values below 2**63: the values below
 * 2**63 to the front of low, the others to the front of high, each in order (branch-free: both slots written,
 * one cursor moved; at step i the cursors sum to i, so neither passes n).
 * twin: (h[h < 2**63], h[h >= 2**63]) */
PyObject *k_split_top_bit(PyObject *self, PyObject *args) {
    Py_buffer h, lo, hi;
    if (!PyArg_ParseTuple(args, "y*w*w*", &h, &lo, &hi)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = h.len / 8, j = 0, k = 0;
    if (!need(&h, n, 8, "h") || !need(&lo, n, 8, "low") || !need(&hi, n, 8, "high")) goto done;
    const uint64_t *x = (const uint64_t *)h.buf;
    uint64_t *L = (uint64_t *)lo.buf, *H = (uint64_t *)hi.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        uint64_t v = x[i], top = v >> 63;
        L[j] = v;
        H[k] = v;
        j += (Py_ssize_t)(1 - top);
        k += (Py_ssize_t)top;
    }
    Py_END_ALLOW_THREADS
    ret = PyLong_FromSsize_t(j);
done:
    PyBuffer_Release(&h);
    PyBuffer_Release(&lo);
    PyBuffer_Release(&hi);
    return ret;
}
