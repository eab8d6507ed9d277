/* _hpe_kernels: hpe's optional compiled column kernels.
 *
 * Each function is one loop over a column where numpy takes a dozen passes or more, or a data-dependent loop
 * numpy cannot express (a hash over each string's bytes); each has a numpy twin in hpe_cli (named in its
 * docstring) that gives the same bits, and tests/native/ compares the two. The hashes and the screens compute
 * integers, fabs, differences and comparisons only. The error kernels add IEEE sums, products and square roots in
 * the order of their twins' numpy operations (the build passes -ffp-contract=off: no fused multiply-adds) and call
 * the C library's sincos and atan2, which hpe_cli.native uses only where they give numpy's bits on a probe of
 * values. The arguments are buffers (numpy arrays), checked for size; the GIL is released in the loops, so the
 * threads that call them run in parallel.
 */
#define _GNU_SOURCE /* sincos */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* constants shared with hpe_cli/io/key_hash.py and hpe_cli/pipelines/audit/duplicates.py */
#define P_FNV 0x100000001B3ULL
#define LEN_MULT 0x9E3779B97F4A7C15ULL
#define NULL_HASH 0xD6E8FEB86659FD93ULL
#define ROW_MULT 0x9FB21C651E98DF25ULL
#define NAN_BITS 0x7FF8000000000000ULL

static inline uint64_t mix64(uint64_t h) {
    h ^= h >> 30;
    h *= 0xBF58476D1CE4E5B9ULL;
    h ^= h >> 27;
    h *= 0x94D049BB133111EBULL;
    h ^= h >> 31;
    return h;
}

static int need(Py_buffer *b, Py_ssize_t items, Py_ssize_t itemsize, const char *name) {
    if (b->len != items * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd bytes, got %zd", name, items * itemsize, b->len);
        return 0;
    }
    return 1;
}

/* string_hashes(offsets int64[n+1], data uint8[], valid uint8[n] or None, out uint64[n], stems uint64[n] or None)
 * twin: hpe_cli.io.key_hash.string_hashes (numpy) */
static inline uint64_t span_hash(const uint8_t *d, int64_t s, int64_t e) {
    uint64_t h = 0;
    for (int64_t k = e - 1; k >= s; k--) h = h * P_FNV + d[k];
    h ^= (uint64_t)(e - s) * LEN_MULT;
    return mix64(h);
}

static PyObject *k_string_hashes(PyObject *self, PyObject *args) {
    Py_buffer off, data, out, valid = {0}, stems = {0};
    PyObject *valid_o, *stems_o;
    if (!PyArg_ParseTuple(args, "y*y*Ow*O", &off, &data, &valid_o, &out, &stems_o)) return NULL;
    PyObject *ret = NULL;
    int have_valid = 0, have_stems = 0;
    Py_ssize_t n = out.len / 8;
    if (valid_o != Py_None) {
        if (PyObject_GetBuffer(valid_o, &valid, PyBUF_SIMPLE) < 0) goto done;
        have_valid = 1;
    }
    if (stems_o != Py_None) {
        if (PyObject_GetBuffer(stems_o, &stems, PyBUF_WRITABLE) < 0) goto done;
        have_stems = 1;
    }
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
static PyObject *k_row_hash_add(PyObject *self, PyObject *args) {
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
static PyObject *k_mix(PyObject *self, PyObject *args) {
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

/* angle_screen(c0, c1, c2 float64[n], finite bool[n], mid, d_lock, d_near, margin, all_unsure,
 *              lo (3 floats), hi (3 floats), gimbal_lock, near_gimbal, non_canonical, out_of_range, unsure bool[n])
 * The audit's screened angle masks before the unsure rows' round trip; comparisons and fabs only (fabs, < and <=
 * are exact in C as in numpy).  twin: hpe_cli.rotation.audit.angle_flags_screened
 * Two rows at a time in GCC/Clang vector types (SSE2 on x86-64; comparisons give -1/0 lanes), the last one
 * alone with the same formulas. */
typedef double v2d __attribute__((vector_size(16)));
typedef int64_t v2i __attribute__((vector_size(16)));

typedef struct {
    double l[3], h[3], e[3]; /* below: c < l, or c == e (e = -180 where lo <= -180, else -inf) */
    double dl, dn, mg, lm, nm; /* lm, nm: 1 where the lock / near threshold has a margin, else 0 */
    int every;
} screen_t;

static inline uint8_t screen_row(const screen_t *S, double v0, double v1, double v2, double m, uint8_t fi,
                                 uint8_t *gl, uint8_t *ng, uint8_t *nc, uint8_t *un) {
    double a = fabs(m), d = fabs(a - 90.0);
    int locked = d < S->dl;
    int inner = (fabs(v0) <= 180.0) & (fabs(v1) <= 180.0) & (fabs(v2) <= 180.0);
    int below = (v0 < S->l[0]) | (v0 == S->e[0]) | (v1 < S->l[1]) | (v1 == S->e[1]) | (v2 < S->l[2]) | (v2 == S->e[2]);
    int above = (v0 > S->h[0]) | (v1 > S->h[1]) | (v2 > S->h[2]);
    int unsure = (!inner) | S->every | ((S->lm > 0.0) & (fabs(d - S->dl) <= S->mg)) |
                 ((S->nm > 0.0) & (fabs(d - S->dn) <= S->mg));
    *gl = (uint8_t)(locked & fi);
    *ng = (uint8_t)((locked | (d < S->dn)) & fi);
    *nc = (uint8_t)((!locked) & (a > 90.0) & fi);
    *un = (uint8_t)(unsure & fi);
    return (uint8_t)(((!inner) | below | above) & fi);
}

static inline v2d vabs(v2d x) {
    v2i m = {INT64_MAX, INT64_MAX};
    return (v2d)((v2i)x & m);
}

static inline v2d vset(double x) { return (v2d){x, x}; }

static inline void screen_pair(const screen_t *S, const double *x0, const double *x1, const double *x2, const double *xm,
                          const uint8_t *F, uint8_t *GL, uint8_t *NG, uint8_t *NC, uint8_t *OR, uint8_t *UN) {
    v2d v0, v1, v2, m;
    memcpy(&v0, x0, 16);
    memcpy(&v1, x1, 16);
    memcpy(&v2, x2, 16);
    memcpy(&m, xm, 16);
    v2d a = vabs(m), d = vabs(a - vset(90.0)), c180 = vset(180.0);
    v2i locked = d < vset(S->dl);
    v2i inner = (vabs(v0) <= c180) & (vabs(v1) <= c180) & (vabs(v2) <= c180);
    v2i below = (v0 < vset(S->l[0])) | (v0 == vset(S->e[0])) | (v1 < vset(S->l[1])) | (v1 == vset(S->e[1])) |
                (v2 < vset(S->l[2])) | (v2 == vset(S->e[2]));
    v2i above = (v0 > vset(S->h[0])) | (v1 > vset(S->h[1])) | (v2 > vset(S->h[2]));
    v2i all = {-S->every, -S->every};
    v2i unsure = ~inner | all | ((vset(S->lm) > vset(0.0)) & (vabs(d - vset(S->dl)) <= vset(S->mg))) |
                 ((vset(S->nm) > vset(0.0)) & (vabs(d - vset(S->dn)) <= vset(S->mg)));
    v2i near = locked | (d < vset(S->dn));
    v2i canon = ~locked & (a > vset(90.0));
    v2i out = ~inner | below | above;
    for (int k = 0; k < 2; k++) {
        uint8_t fi = F[k] != 0;
        GL[k] = (uint8_t)(locked[k] & 1) & fi;
        NG[k] = (uint8_t)(near[k] & 1) & fi;
        NC[k] = (uint8_t)(canon[k] & 1) & fi;
        OR[k] = (uint8_t)(out[k] & 1) & fi;
        UN[k] = (uint8_t)(unsure[k] & 1) & fi;
    }
}

static PyObject *k_angle_screen(PyObject *self, PyObject *args) {
    Py_buffer c[3], fin, o[5];
    int mid, all_unsure;
    double d_lock, d_near, margin, lo[3], hi[3];
    if (!PyArg_ParseTuple(args, "y*y*y*y*idddp(ddd)(ddd)w*w*w*w*w*", &c[0], &c[1], &c[2], &fin, &mid, &d_lock,
                          &d_near, &margin, &all_unsure, &lo[0], &lo[1], &lo[2], &hi[0], &hi[1], &hi[2], &o[0], &o[1],
                          &o[2], &o[3], &o[4]))
        return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = fin.len;
    int ok = 1;
    for (int k = 0; k < 3 && ok; k++) ok = need(&c[k], n, 8, "angles");
    for (int k = 0; k < 5 && ok; k++) ok = need(&o[k], n, 1, "masks");
    if (ok && (mid < 0 || mid > 2)) {
        PyErr_SetString(PyExc_ValueError, "mid: expected 0, 1 or 2");
        ok = 0;
    }
    if (!ok) goto done;
    screen_t S;
    for (int k = 0; k < 3; k++) {
        S.l[k] = lo[k] > -180.0 ? lo[k] : -180.0; /* (c <= -180) | (c < lo) is c < lo above -180, else c <= -180 */
        S.e[k] = lo[k] > -180.0 ? -INFINITY : -180.0;
        S.h[k] = hi[k];
    }
    S.dl = d_lock, S.dn = d_near, S.mg = margin, S.lm = d_lock >= 0.0, S.nm = d_near >= 0.0, S.every = all_unsure != 0;
    const double *x[3] = {(const double *)c[0].buf, (const double *)c[1].buf, (const double *)c[2].buf};
    const uint8_t *F = (const uint8_t *)fin.buf;
    uint8_t *GL = (uint8_t *)o[0].buf, *NG = (uint8_t *)o[1].buf, *NC = (uint8_t *)o[2].buf;
    uint8_t *OR = (uint8_t *)o[3].buf, *UN = (uint8_t *)o[4].buf;
    Py_BEGIN_ALLOW_THREADS
    Py_ssize_t i = 0;
    for (; i + 2 <= n; i += 2)
        screen_pair(&S, x[0] + i, x[1] + i, x[2] + i, x[mid] + i, F + i, GL + i, NG + i, NC + i, OR + i, UN + i);
    for (; i < n; i++)
        OR[i] = screen_row(&S, x[0][i], x[1][i], x[2][i], x[mid][i], F[i] != 0, GL + i, NG + i, NC + i, UN + i);
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    for (int k = 0; k < 3; k++) PyBuffer_Release(&c[k]);
    PyBuffer_Release(&fin);
    for (int k = 0; k < 5; k++) PyBuffer_Release(&o[k]);
    return ret;
}

/* sin_cos(x float64[n], s float64[n], c float64[n]): s = sin(x), c = cos(x) by the C library's one call for both
 * (glibc's sincos: the same reduction and polynomials as its sin and cos, so the same bits; elsewhere sin and cos).
 * Transcendental: hpe_cli.native.sin_cos uses it only where it gives numpy's bits on a probe of values.
 * twin: np.sin(x), np.cos(x) */
static PyObject *k_sin_cos(PyObject *self, PyObject *args) {
    Py_buffer x, s, c;
    if (!PyArg_ParseTuple(args, "y*w*w*", &x, &s, &c)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = x.len / 8;
    if (!need(&x, n, 8, "x") || !need(&s, n, 8, "sin") || !need(&c, n, 8, "cos")) goto done;
    const double *X = (const double *)x.buf;
    double *S = (double *)s.buf, *C = (double *)c.buf;
    Py_BEGIN_ALLOW_THREADS
#if defined(__GLIBC__)
    for (Py_ssize_t i = 0; i < n; i++) sincos(X[i], S + i, C + i);
#else
    for (Py_ssize_t i = 0; i < n; i++) {
        S[i] = sin(X[i]);
        C[i] = cos(X[i]);
    }
#endif
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&x);
    PyBuffer_Release(&s);
    PyBuffer_Release(&c);
    return ret;
}

/* core_errors(P (9 float64[n] columns, row-major), G (9 columns), geo float64[n], maev float64[n*3], fro float64[n])
 * The geodesic angle of P G^T (atan2 of half its skew norm and half of trace - 1), the angle between each column of
 * P and of G (atan2 of the cross product's norm and the dot product) and ||P - G||_F, in degrees, in the order of
 * the numpy twins' operations (left to right; no fused multiply-adds). Uses the C library's atan2: hpe_cli.native
 * calls it only where atan2 gives numpy's bits on a probe.
 * twins: hpe_cli.metrics.rotation_errors.geodesic_deg, maev_deg, frobenius */
static int nine(PyObject *seq, Py_buffer *b, Py_ssize_t n, const char *name) {
    PyObject *fast = PySequence_Fast(seq, "expected a sequence of 9 columns");
    if (!fast) return 0;
    if (PySequence_Fast_GET_SIZE(fast) != 9) {
        PyErr_Format(PyExc_ValueError, "%s: expected 9 columns, got %zd", name, PySequence_Fast_GET_SIZE(fast));
        Py_DECREF(fast);
        return 0;
    }
    int k = 0;
    for (; k < 9; k++) {
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(fast, k), &b[k], PyBUF_C_CONTIGUOUS) < 0) break;
        if (!need(&b[k], n, 8, name)) {
            k++;
            break;
        }
    }
    Py_DECREF(fast);
    if (k == 9 && !PyErr_Occurred()) return 1;
    for (int j = 0; j < k; j++) PyBuffer_Release(&b[j]);
    return 0;
}

static PyObject *k_core_errors(PyObject *self, PyObject *args) {
    PyObject *Po, *Go;
    Py_buffer geo, maev, fro, P[9], G[9];
    if (!PyArg_ParseTuple(args, "OOw*w*w*", &Po, &Go, &geo, &maev, &fro)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = geo.len / 8;
    int have_p = 0, have_g = 0;
    if (!need(&geo, n, 8, "geo") || !need(&maev, 3 * n, 8, "maev") || !need(&fro, n, 8, "fro")) goto done;
    if (!(have_p = nine(Po, P, n, "P")) || !(have_g = nine(Go, G, n, "G"))) goto done;
    const double *p[9], *g[9];
    for (int k = 0; k < 9; k++) p[k] = (const double *)P[k].buf, g[k] = (const double *)G[k].buf;
    double *GEO = (double *)geo.buf, *MA = (double *)maev.buf, *FR = (double *)fro.buf;
    const double DEG = 180.0 / 3.141592653589793;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double a[9], b[9];
        for (int k = 0; k < 9; k++) a[k] = p[k][i], b[k] = g[k][i];
#define M(k, l) (a[3 * (k)] * b[3 * (l)] + a[3 * (k) + 1] * b[3 * (l) + 1] + a[3 * (k) + 2] * b[3 * (l) + 2])
        double tr = M(0, 0) + M(1, 1) + M(2, 2);
        double sx = M(2, 1) - M(1, 2), sy = M(0, 2) - M(2, 0), sz = M(1, 0) - M(0, 1);
#undef M
        double two_sin = sqrt(sx * sx + sy * sy + sz * sz);
        GEO[i] = atan2(0.5 * two_sin, 0.5 * (tr - 1.0)) * DEG;
        for (int j = 0; j < 3; j++) { /* column j of P and of G */
            double p0 = a[j], p1 = a[3 + j], p2 = a[6 + j], g0 = b[j], g1 = b[3 + j], g2 = b[6 + j];
            double dot = p0 * g0;
            dot += p1 * g1;
            dot += p2 * g2;
            double cx = p1 * g2 - p2 * g1, cy = p2 * g0 - p0 * g2, cz = p0 * g1 - p1 * g0;
            double norm = cx * cx;
            norm += cy * cy;
            norm += cz * cz;
            MA[3 * i + j] = atan2(sqrt(norm), dot) * DEG;
        }
        double acc = 0.0;
        for (int k = 0; k < 9; k++) {
            double d = a[k] - b[k];
            acc = k ? acc + d * d : 0.0 + d * d;
        }
        FR[i] = sqrt(acc);
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_p)
        for (int k = 0; k < 9; k++) PyBuffer_Release(&P[k]);
    if (have_g)
        for (int k = 0; k < 9; k++) PyBuffer_Release(&G[k]);
    PyBuffer_Release(&geo);
    PyBuffer_Release(&maev);
    PyBuffer_Release(&fro);
    return ret;
}

/* atan2(y float64[n], x float64[n], out float64[n]): the C library's, for hpe_cli.native's probe */
static PyObject *k_atan2(PyObject *self, PyObject *args) {
    Py_buffer y, x, o;
    if (!PyArg_ParseTuple(args, "y*y*w*", &y, &x, &o)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = o.len / 8;
    if (!need(&y, n, 8, "y") || !need(&x, n, 8, "x") || !need(&o, n, 8, "out")) goto done;
    const double *Y = (const double *)y.buf, *X = (const double *)x.buf;
    double *O = (double *)o.buf;
    for (Py_ssize_t i = 0; i < n; i++) O[i] = atan2(Y[i], X[i]);
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&y);
    PyBuffer_Release(&x);
    PyBuffer_Release(&o);
    return ret;
}

/* split_top_bit(h uint64[n], low uint64[n], high uint64[n]) -> number of values below 2**63: the values below
 * 2**63 to the front of low, the others to the front of high, each in order (branch-free: both slots written,
 * one cursor moved; at step i the cursors sum to i, so neither passes n).
 * twin: (h[h < 2**63], h[h >= 2**63]) */
static PyObject *k_split_top_bit(PyObject *self, PyObject *args) {
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

/* repeated_values(h uint64[n] in place) -> k: each value that occurs more than once in h, once, to h[0..k), in
 * increasing order; the rest of h is left in some order (h is scratch).  twin: np.sort, then the values equal to
 * their successor (hpe_cli.pipelines.audit.duplicates.repeated_in_place)
 * Most significant digit first: h is partitioned in place by its top RADIX_BITS bits (American flag sort) into
 * buckets in increasing order, each bucket again by the next bits until it has at most LEAF values (or every bit is
 * used: its values are then equal). A leaf's values go through a hash set in cache (open addressing, at least four
 * slots a value, 0 marking an empty slot and the value 0 counted aside); every later occurrence of a value is
 * written out, and the leaf's output is sorted and made unique. An occurrence is written to h[k] with k below the
 * number of values read so far, i.e. below the value being read: the values still to read are never overwritten.
 * At 5M random values (one audit half of 10M rows): 0.75x the CPU of numpy's sort, half of it the partition. */
#define RADIX_BITS 10
#define LEAF 16384

typedef struct {
    uint64_t *keys; /* 4 * LEAF slots: a leaf's hash set */
    uint64_t *h;
    Py_ssize_t k; /* repeats written */
    int failed;   /* no memory for a bucket's counts */
} repeats_t;

static void sort_small(uint64_t *a, Py_ssize_t n) {
    for (Py_ssize_t i = 1; i < n; i++) {
        uint64_t v = a[i];
        Py_ssize_t j = i;
        for (; j > 0 && a[j - 1] > v; j--) a[j] = a[j - 1];
        a[j] = v;
    }
}

static void sort_u64(uint64_t *a, Py_ssize_t n); /* below: for leaves with many repeats */

static void leaf_repeats(repeats_t *R, Py_ssize_t lo, Py_ssize_t hi) {
    Py_ssize_t n = hi - lo, size = 16;
    while (size < 4 * n) size *= 2;
    int sh = 64;
    for (Py_ssize_t s = size; s > 1; s >>= 1) sh--;
    uint64_t *keys = R->keys, *h = R->h, zeros = 0; /* 0 marks an empty slot; the value 0 is counted aside */
    memset(keys, 0, (size_t)size * sizeof(uint64_t));
    Py_ssize_t k0 = R->k, mask = size - 1;
    for (Py_ssize_t i = lo; i < hi; i++) {
        uint64_t v = h[i];
        if (v == 0) {
            if (zeros++) h[R->k++] = 0;
            continue;
        }
        Py_ssize_t s = (Py_ssize_t)((v * 0x9E3779B97F4A7C15ULL) >> sh);
        uint64_t x;
        while ((x = keys[s]) != 0 && x != v) s = (s + 1) & mask;
        if (x == 0)
            keys[s] = v;
        else
            h[R->k++] = v; /* a second or later occurrence: duplicates removed below */
    }
    Py_ssize_t m = R->k - k0;
    if (m > 64)
        sort_u64(h + k0, m);
    else
        sort_small(h + k0, m);
    Py_ssize_t j = k0;
    for (Py_ssize_t i = k0; i < k0 + m; i++)
        if (i == k0 || h[i] != h[i - 1]) h[j++] = h[i];
    R->k = j;
}

static void bucket_repeats(repeats_t *R, Py_ssize_t lo, Py_ssize_t hi, int shift) {
    Py_ssize_t n = hi - lo;
    if (n < 2 || R->failed) return;
    if (shift == 0) { /* every bit used: the values are equal */
        R->h[R->k++] = R->h[lo];
        return;
    }
    if (n <= LEAF) {
        leaf_repeats(R, lo, hi);
        return;
    }
    int bits = 1; /* enough digits for leaves of about LEAF / 2 values, at most RADIX_BITS */
    while (bits < RADIX_BITS && ((Py_ssize_t)LEAF << bits) < 2 * n) bits++;
    if (bits > shift) bits = shift;
    int sh = shift - bits;
    Py_ssize_t nb = (Py_ssize_t)1 << bits;
    uint64_t mask = (uint64_t)nb - 1, *h = R->h;
    Py_ssize_t *start = calloc((size_t)(2 * nb + 1), sizeof(Py_ssize_t)), *head = start + nb + 1;
    if (start == NULL) {
        R->failed = 1;
        return;
    }
    for (Py_ssize_t i = lo; i < hi; i++) start[((h[i] >> sh) & mask) + 1]++;
    start[0] = lo;
    for (Py_ssize_t b = 0; b < nb; b++) {
        start[b + 1] += start[b];
        head[b] = start[b];
    }
    for (Py_ssize_t b = 0; b < nb; b++) { /* cycle leader: each value moved once to its bucket */
        while (head[b] < start[b + 1]) {
            uint64_t v = h[head[b]];
            Py_ssize_t d = (Py_ssize_t)((v >> sh) & mask);
            while (d != b) {
                uint64_t t = h[head[d]];
                h[head[d]++] = v;
                v = t;
                d = (Py_ssize_t)((v >> sh) & mask);
            }
            h[head[b]++] = v;
        }
    }
    for (Py_ssize_t b = 0; b < nb; b++) bucket_repeats(R, start[b], start[b + 1], sh);
    free(start);
}

/* heap sort (no recursion, no memory): a leaf's repeats when there are many */
static void sift_down(uint64_t *a, Py_ssize_t i, Py_ssize_t n) {
    uint64_t v = a[i];
    for (Py_ssize_t c = 2 * i + 1; c < n; c = 2 * i + 1) {
        if (c + 1 < n && a[c + 1] > a[c]) c++;
        if (a[c] <= v) break;
        a[i] = a[c];
        i = c;
    }
    a[i] = v;
}

static void sort_u64(uint64_t *a, Py_ssize_t n) {
    for (Py_ssize_t i = n / 2 - 1; i >= 0; i--) sift_down(a, i, n);
    for (Py_ssize_t e = n - 1; e > 0; e--) {
        uint64_t t = a[0];
        a[0] = a[e];
        a[e] = t;
        sift_down(a, 0, e);
    }
}

static PyObject *k_repeated_values(PyObject *self, PyObject *args) {
    Py_buffer h;
    if (!PyArg_ParseTuple(args, "w*", &h)) return NULL;
    Py_ssize_t n = h.len / 8;
    if (!need(&h, n, 8, "h")) {
        PyBuffer_Release(&h);
        return NULL;
    }
    repeats_t R = {malloc(4 * LEAF * sizeof(uint64_t)), (uint64_t *)h.buf, 0, 0};
    if (R.keys == NULL) {
        PyBuffer_Release(&h);
        return PyErr_NoMemory();
    }
    Py_BEGIN_ALLOW_THREADS
    bucket_repeats(&R, 0, n, 64);
    Py_END_ALLOW_THREADS
    free(R.keys);
    PyBuffer_Release(&h);
    if (R.failed) return PyErr_NoMemory();
    return PyLong_FromSsize_t(R.k);
}

/* The audit's hashes by bucket as they stream, so that the end of the run finds the repeats bucket by bucket in cache:
 * with B = len(cursors) buckets (a power of two, 2**bits), bucket b (the top bits of a value) owns
 * arr[b * cap, (b + 1) * cap); cursors[b] counts the values it was given. Both are shared by the threads that check the batches (the cursors move by atomic additions, each batch
 * reserving its run in every bucket), so the values of a bucket are in some order that does not matter.
 * bucket_file(h uint64[n], arr uint64[B * cap], cursors int64[B], cap) -> True, or False
 * when a bucket is full (its values beyond cap are dropped: the caller then finds the repeats another way).
 * bucket_repeats(arr, cursors, cap, b_lo, b_hi) -> bytes: the repeated values of buckets b_lo .. b_hi - 1, once
 * each, in increasing order (as repeated_values; the buckets' regions are scratch).
 * twin: hpe_cli.pipelines.audit.duplicates.repeated_in_place of the values (numpy's sort) */

/* the bits of the bucket count, from the cursors' buffer (a power of two from 2 to 2**16), or -1 */
static int bucket_bits(Py_buffer *c) {
    Py_ssize_t nb = c->len / 8;
    int bits = 1;
    while (bits <= 16 && ((Py_ssize_t)1 << bits) != nb) bits++;
    if (bits > 16 || c->len != nb * 8) {
        PyErr_Format(PyExc_ValueError, "cursors: expected 2**k int64 values (k = 1 .. 16), got %zd bytes", c->len);
        return -1;
    }
    return bits;
}

static PyObject *k_bucket_file(PyObject *self, PyObject *args) {
    Py_buffer h, a, c;
    Py_ssize_t cap;
    if (!PyArg_ParseTuple(args, "y*w*w*n", &h, &a, &c, &cap)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = h.len / 8;
    int bits = bucket_bits(&c);
    if (bits < 0) goto done;
    const int nb = 1 << bits;
    if (cap < 1 || !need(&h, n, 8, "h") || !need(&a, nb * cap, 8, "arr")) goto done;
    const uint64_t *x = (const uint64_t *)h.buf;
    uint64_t *arr = (uint64_t *)a.buf;
    int64_t *cur = (int64_t *)c.buf;
    int full = 0;
    Py_BEGIN_ALLOW_THREADS
    int64_t *at = calloc(2 * nb, sizeof(int64_t)), *end = at ? at + nb : NULL;
    if (at == NULL) {
        full = 2;
    } else {
        for (Py_ssize_t i = 0; i < n; i++) at[x[i] >> (64 - bits)]++;
        for (int b = 0; b < nb; b++) {
            int64_t k = at[b], s = k ? __atomic_fetch_add(&cur[b], k, __ATOMIC_RELAXED) : 0;
            if (s + k > cap) full = 1;
            at[b] = s < cap ? (int64_t)b * cap + s : (int64_t)(b + 1) * cap;
            end[b] = (int64_t)(b + 1) * cap;
        }
        for (Py_ssize_t i = 0; i < n; i++) {
            uint64_t v = x[i];
            int b = (int)(v >> (64 - bits));
            if (at[b] < end[b]) arr[at[b]++] = v;
        }
        free(at);
    }
    Py_END_ALLOW_THREADS
    if (full == 2)
        PyErr_NoMemory();
    else
        ret = PyBool_FromLong(!full);
done:
    PyBuffer_Release(&h);
    PyBuffer_Release(&a);
    PyBuffer_Release(&c);
    return ret;
}

static PyObject *k_bucket_repeats(PyObject *self, PyObject *args) {
    Py_buffer a, c;
    Py_ssize_t cap, lo, hi;
    if (!PyArg_ParseTuple(args, "w*y*nnn", &a, &c, &cap, &lo, &hi)) return NULL;
    PyObject *ret = NULL;
    int bits = bucket_bits(&c);
    if (bits < 0) goto done;
    const Py_ssize_t nb = (Py_ssize_t)1 << bits;
    if (cap < 1 || lo < 0 || hi > nb || lo > hi) {
        PyErr_Format(PyExc_ValueError, "expected 0 <= lo <= hi <= %zd buckets and cap >= 1, got %zd, %zd, %zd", nb,
                     lo, hi, cap);
        goto done;
    }
    if (!need(&a, nb * cap, 8, "arr")) goto done;
    uint64_t *arr = (uint64_t *)a.buf, *out = NULL;
    const int64_t *cur = (const int64_t *)c.buf;
    Py_ssize_t k = 0, size = 0;
    int failed = 0;
    repeats_t R = {malloc(4 * LEAF * sizeof(uint64_t)), NULL, 0, 0};
    Py_BEGIN_ALLOW_THREADS
    failed = R.keys == NULL;
    for (Py_ssize_t b = lo; b < hi && !failed; b++) {
        Py_ssize_t m = cur[b] < cap ? (Py_ssize_t)cur[b] : cap;
        R.h = arr + b * cap;
        R.k = 0;
        bucket_repeats(&R, 0, m, 64 - bits); /* the repeats to the front of the bucket's region */
        if (R.failed) failed = 1;
        if (k + R.k > size) {
            Py_ssize_t want = 2 * (k + R.k) + 64;
            uint64_t *grown = realloc(out, (size_t)want * sizeof(uint64_t));
            if (grown == NULL) {
                failed = 1;
                break;
            }
            out = grown, size = want;
        }
        memcpy(out + k, R.h, (size_t)R.k * sizeof(uint64_t));
        k += R.k;
    }
    Py_END_ALLOW_THREADS
    free(R.keys);
    if (failed)
        PyErr_NoMemory();
    else
        ret = PyBytes_FromStringAndSize(k ? (const char *)out : "", k * (Py_ssize_t)sizeof(uint64_t));
    free(out);
done:
    PyBuffer_Release(&a);
    PyBuffer_Release(&c);
    return ret;
}

static PyMethodDef methods[] = {
    {"split_top_bit", k_split_top_bit, METH_VARARGS,
     "split_top_bit(h, low, high) -> n_low: the hashes by value half, in order (twin: a boolean index)."},
    {"string_hashes", k_string_hashes, METH_VARARGS,
     "string_hashes(offsets, data, valid, out, stems): 64-bit hashes of Arrow strings (twin: "
     "hpe_cli.io.key_hash.string_hashes)."},
    {"row_hash_add", k_row_hash_add, METH_VARARGS,
     "row_hash_add(h, words, is_float): one column into the audit's row hashes (twin: "
     "hpe_cli.pipelines.audit.duplicates.key_hashes)."},
    {"mix", k_mix, METH_VARARGS, "mix(h): SplitMix64's finaliser in place (twin: hpe_cli.io.key_hash.mix)."},
    {"angle_screen", k_angle_screen, METH_VARARGS,
     "angle_screen(...): the audit's screened angle masks (twin: hpe_cli.rotation.audit.angle_flags_screened)."},
    {"sin_cos", k_sin_cos, METH_VARARGS, "sin_cos(x, s, c): sine and cosine in one call (twin: np.sin, np.cos)."},
    {"core_errors", k_core_errors, METH_VARARGS,
     "core_errors(P, G, geo, maev, fro): geodesic, column angles and Frobenius distance (twins: "
     "hpe_cli.metrics.rotation_errors)."},
    {"atan2", k_atan2, METH_VARARGS, "atan2(y, x, out): the C library's atan2 (for the probe)."},
    {"repeated_values", k_repeated_values, METH_VARARGS,
     "repeated_values(h) -> k: the repeated values of h, once each and sorted, to h[:k] (h is scratch; twin: "
     "hpe_cli.pipelines.audit.duplicates.repeated_in_place)."},
    {"bucket_file", k_bucket_file, METH_VARARGS,
     "bucket_file(h, arr, cursors, cap) -> bool: a batch's hashes to their buckets (False: a bucket is full)."},
    {"bucket_repeats", k_bucket_repeats, METH_VARARGS,
     "bucket_repeats(arr, cursors, cap, lo, hi) -> bytes: the repeated values of buckets lo .. hi - 1, sorted "
     "(twin: hpe_cli.pipelines.audit.duplicates.repeated_in_place)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_hpe_kernels",
                                    "hpe's optional compiled column kernels (csrc/_hpe_kernels.c).", -1, methods};

PyMODINIT_FUNC PyInit__hpe_kernels(void) { return PyModule_Create(&module); }
