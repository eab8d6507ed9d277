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

/* ---- evaluate's key join (pipelines/evaluate/spill.py): pairing by 64-bit key hash, verification on the bytes ---- */

/* hash_pairs(hg uint64[ng], hp uint64[np], pos int64[ng]) -> bool: pos[i] = the row of hp whose value equals
 * hg[i], else -1; False (pos unspecified) when a value repeats on one side. Radix-partitioned by the top bits
 * (buckets of about 2,048 rows of both sides), then one open-addressing table per bucket, which stays in the
 * caches: no random access over the whole arrays but the writes to pos.
 * twin: hpe_cli.pipelines.evaluate.spill.hash_matches (numpy: one sort of both sides) */
static int pair_buckets(const uint64_t *hg, Py_ssize_t ng, const uint64_t *hp, Py_ssize_t np_, int64_t *pos) {
    Py_ssize_t total = ng + np_;
    int bits = 0;
    while (bits < 24 && (total >> bits) > 4096) bits++;
    Py_ssize_t nb = (Py_ssize_t)1 << bits;
    int shift = 64 - bits;
    Py_ssize_t *start = calloc((size_t)(2 * nb + 2), sizeof(Py_ssize_t));
    uint64_t *sh = malloc((size_t)(total ? total : 1) * sizeof(uint64_t));
    int64_t *sr = malloc((size_t)(total ? total : 1) * sizeof(int64_t));
    int status = 1;
    if (!start || !sh || !sr) {
        status = -1;
        goto out;
    }
    /* bucket b of side s (0 GT, 1 prediction) at [start[2b+s], start[2b+s+1]): a bucket's GT rows, then its
     * predictions, each in row order */
    for (Py_ssize_t i = 0; i < ng; i++) start[2 * (bits ? hg[i] >> shift : 0) + 1]++;
    for (Py_ssize_t i = 0; i < np_; i++) start[2 * (bits ? hp[i] >> shift : 0) + 2]++;
    for (Py_ssize_t b = 1; b <= 2 * nb; b++) start[b] += start[b - 1];
    Py_ssize_t *cur = malloc((size_t)(2 * nb) * sizeof(Py_ssize_t));
    if (!cur) {
        status = -1;
        goto out;
    }
    memcpy(cur, start, (size_t)(2 * nb) * sizeof(Py_ssize_t));
    for (Py_ssize_t i = 0; i < ng; i++) {
        Py_ssize_t at = cur[2 * (bits ? hg[i] >> shift : 0)]++;
        sh[at] = hg[i];
        sr[at] = i;
    }
    for (Py_ssize_t i = 0; i < np_; i++) {
        Py_ssize_t at = cur[2 * (bits ? hp[i] >> shift : 0) + 1]++;
        sh[at] = hp[i];
        sr[at] = i;
    }
    free(cur);
    Py_ssize_t biggest = 0;
    for (Py_ssize_t b = 0; b < nb; b++)
        if (start[2 * b + 2] - start[2 * b] > biggest) biggest = start[2 * b + 2] - start[2 * b];
    size_t cap = 16;
    while (cap < (size_t)(2 * biggest)) cap <<= 1;
    int32_t *table = malloc(cap * sizeof(int32_t)); /* slot: 1 + the bucket-local index of a GT row, 0 empty */
    if (!table) {
        status = -1;
        goto out;
    }
    for (Py_ssize_t b = 0; b < nb && status == 1; b++) {
        Py_ssize_t g0 = start[2 * b], p0 = start[2 * b + 1], p1 = start[2 * b + 2];
        size_t m = 16;
        while (m < (size_t)(2 * (p1 - g0))) m <<= 1;
        memset(table, 0, m * sizeof(int32_t));
        for (Py_ssize_t j = g0; j < p0; j++) {
            size_t s = (size_t)sh[j] & (m - 1);
            while (table[s]) {
                if (sh[g0 + table[s] - 1] == sh[j]) {
                    status = 0; /* twice among the GT rows */
                    break;
                }
                s = (s + 1) & (m - 1);
            }
            if (!status) break;
            table[s] = (int32_t)(j - g0 + 1);
            pos[sr[j]] = -1;
        }
        for (Py_ssize_t j = p0; j < p1 && status == 1; j++) {
            size_t s = (size_t)sh[j] & (m - 1);
            while (table[s]) {
                Py_ssize_t k = g0 + table[s] - 1;
                if (sh[k] == sh[j]) {
                    if (k >= p0) { /* an earlier prediction with this hash */
                        status = 0;
                        break;
                    }
                    if (pos[sr[k]] >= 0) { /* the GT row already has a prediction: this one repeats it */
                        status = 0;
                        break;
                    }
                    pos[sr[k]] = sr[j];
                    goto next_pred;
                }
                s = (s + 1) & (m - 1);
            }
            if (status != 1) break;
            table[s] = (int32_t)(j - g0 + 1); /* a prediction with no GT row: kept to find its repeats */
        next_pred:;
        }
    }
    free(table);
out:
    free(start);
    free(sh);
    free(sr);
    return status;
}

static PyObject *k_hash_pairs(PyObject *self, PyObject *args) {
    Py_buffer g, p, o;
    if (!PyArg_ParseTuple(args, "y*y*w*", &g, &p, &o)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t ng = g.len / 8, np_ = p.len / 8;
    if (!need(&g, ng, 8, "hg") || !need(&p, np_, 8, "hp") || !need(&o, ng, 8, "pos")) goto done;
    if (ng + np_ > INT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "hash_pairs: expected at most 2**31 - 1 rows");
        goto done;
    }
    int status;
    Py_BEGIN_ALLOW_THREADS
    status = pair_buckets((const uint64_t *)g.buf, ng, (const uint64_t *)p.buf, np_, (int64_t *)o.buf);
    Py_END_ALLOW_THREADS
    if (status < 0) {
        PyErr_NoMemory();
        goto done;
    }
    ret = PyBool_FromLong(status);
done:
    PyBuffer_Release(&g);
    PyBuffer_Release(&p);
    PyBuffer_Release(&o);
    return ret;
}

/* first_unequal(off_a int32|int64[], data_a, rows_a int64[m] or None, off_b, data_b, rows_b int64[m], wide_a,
 * wide_b) -> int: the first pair j whose strings a[rows_a[j]] (a[j] without rows_a) and b[rows_b[j]] differ in
 * bytes, or -1. Offsets are Arrow's (the array's own offset applied by the caller: a view of its buffer).
 * twin: pyarrow.compute.equal over a.take(rows_a), b.take(rows_b) (spill.Partitions.codes) */
static PyObject *k_first_unequal(PyObject *self, PyObject *args) {
    Py_buffer oa, da, ob, db, rb, ra = {0};
    PyObject *ra_o;
    int wa, wb;
    if (!PyArg_ParseTuple(args, "y*y*Oy*y*y*pp", &oa, &da, &ra_o, &ob, &db, &rb, &wa, &wb)) return NULL;
    PyObject *ret = NULL;
    int have_ra = 0;
    Py_ssize_t m = rb.len / 8, j, bad = -1;
    Py_ssize_t na = oa.len / (wa ? 8 : 4) - 1, nb = ob.len / (wb ? 8 : 4) - 1;
    if (ra_o != Py_None) {
        if (PyObject_GetBuffer(ra_o, &ra, PyBUF_SIMPLE) < 0) goto done;
        have_ra = 1;
    }
    if (!need(&rb, m, 8, "rows_b") || (have_ra && !need(&ra, m, 8, "rows_a"))) goto done;
    if (na < (have_ra ? 0 : m) || nb < 0) {
        PyErr_SetString(PyExc_ValueError, "first_unequal: expected offsets of at least one more than the rows");
        goto done;
    }
    const int64_t *RA = have_ra ? (const int64_t *)ra.buf : NULL, *RB = (const int64_t *)rb.buf;
    for (j = 0; j < m; j++)
        if ((RA && (RA[j] < 0 || RA[j] >= na)) || RB[j] < 0 || RB[j] >= nb) {
            PyErr_SetString(PyExc_ValueError, "first_unequal: expected rows within the arrays");
            goto done;
        }
    const uint8_t *A = (const uint8_t *)da.buf, *B = (const uint8_t *)db.buf;
    int ok = 1;
    Py_BEGIN_ALLOW_THREADS
    for (j = 0; j < m; j++) {
        int64_t i = RA ? RA[j] : j, k = RB[j];
        int64_t s0 = wa ? ((const int64_t *)oa.buf)[i] : ((const int32_t *)oa.buf)[i];
        int64_t e0 = wa ? ((const int64_t *)oa.buf)[i + 1] : ((const int32_t *)oa.buf)[i + 1];
        int64_t s1 = wb ? ((const int64_t *)ob.buf)[k] : ((const int32_t *)ob.buf)[k];
        int64_t e1 = wb ? ((const int64_t *)ob.buf)[k + 1] : ((const int32_t *)ob.buf)[k + 1];
        if (s0 < 0 || e0 < s0 || e0 > da.len || s1 < 0 || e1 < s1 || e1 > db.len) {
            ok = 0;
            break;
        }
        if (e0 - s0 != e1 - s1 || memcmp(A + s0, B + s1, (size_t)(e0 - s0))) {
            bad = j;
            break;
        }
    }
    Py_END_ALLOW_THREADS
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "first_unequal: expected increasing offsets within the data");
        goto done;
    }
    ret = PyLong_FromSsize_t(bad);
done:
    PyBuffer_Release(&oa);
    PyBuffer_Release(&da);
    PyBuffer_Release(&ob);
    PyBuffer_Release(&db);
    PyBuffer_Release(&rb);
    if (have_ra) PyBuffer_Release(&ra);
    return ret;
}

/* partition_scatter(part int16[n], K, bounds int64[K+1], srcs tuple, dsts tuple, widths tuple): a stable counting
 * sort of the rows by partition: row i of each source (width bytes a row) goes to its destination at
 * bounds[part[i]] + the rows of that partition before it; bounds[k] = the rows of the partitions before k.
 * twin: order = np.argsort(part, kind="stable"); dst = src[order] (spill._SideSpill.prepare) */
static int count_parts(const int16_t *part, Py_ssize_t n, Py_ssize_t K, int64_t *bounds) {
    memset(bounds, 0, (size_t)(K + 1) * sizeof(int64_t));
    for (Py_ssize_t i = 0; i < n; i++) {
        if (part[i] < 0 || part[i] >= K) return 0;
        bounds[part[i] + 1]++;
    }
    for (Py_ssize_t k = 1; k <= K; k++) bounds[k] += bounds[k - 1];
    return 1;
}

static void scatter_rows(const int16_t *part, Py_ssize_t n, const int64_t *bounds, int64_t *cur, Py_ssize_t K,
                         const uint8_t *src, uint8_t *dst, Py_ssize_t w) {
    memcpy(cur, bounds, (size_t)K * sizeof(int64_t));
    if (w == 8) {
        const uint64_t *a = (const uint64_t *)src;
        uint64_t *b = (uint64_t *)dst;
        for (Py_ssize_t i = 0; i < n; i++) b[cur[part[i]]++] = a[i];
    } else if (w == 1) {
        for (Py_ssize_t i = 0; i < n; i++) dst[cur[part[i]]++] = src[i];
    } else if (w == 24) {
        for (Py_ssize_t i = 0; i < n; i++) memcpy(dst + 24 * cur[part[i]]++, src + 24 * i, 24);
    } else {
        for (Py_ssize_t i = 0; i < n; i++) memcpy(dst + w * cur[part[i]]++, src + w * i, (size_t)w);
    }
}

static PyObject *k_partition_scatter(PyObject *self, PyObject *args) {
    Py_buffer pt, bd;
    Py_ssize_t K;
    PyObject *srcs, *dsts, *widths;
    if (!PyArg_ParseTuple(args, "y*nw*O!O!O!", &pt, &K, &bd, &PyTuple_Type, &srcs, &PyTuple_Type, &dsts,
                          &PyTuple_Type, &widths))
        return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = pt.len / 2, m = PyTuple_GET_SIZE(srcs), j, got = 0;
    Py_buffer *sb = calloc((size_t)(2 * m + 1), sizeof(Py_buffer));
    Py_ssize_t *w = calloc((size_t)(m + 1), sizeof(Py_ssize_t));
    int64_t *cur = malloc((size_t)(K > 0 ? K : 1) * sizeof(int64_t));
    if (!sb || !w || !cur) {
        PyErr_NoMemory();
        goto done;
    }
    if (K < 1 || K > 32767 || !need(&pt, n, 2, "part") || !need(&bd, K + 1, 8, "bounds")) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "partition_scatter: expected 1 <= K <= 32767");
        goto done;
    }
    if (PyTuple_GET_SIZE(dsts) != m || PyTuple_GET_SIZE(widths) != m) {
        PyErr_SetString(PyExc_ValueError, "partition_scatter: expected as many destinations and widths as sources");
        goto done;
    }
    for (j = 0; j < m; j++, got++) {
        w[j] = PyLong_AsSsize_t(PyTuple_GET_ITEM(widths, j));
        if (w[j] < 1 && !PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "partition_scatter: expected widths >= 1");
        if (PyErr_Occurred()) goto done;
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(srcs, j), &sb[2 * j], PyBUF_SIMPLE) < 0) goto done;
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(dsts, j), &sb[2 * j + 1], PyBUF_WRITABLE) < 0) {
            PyBuffer_Release(&sb[2 * j]);
            goto done;
        }
        if (!need(&sb[2 * j], n, w[j], "source") || !need(&sb[2 * j + 1], n, w[j], "destination")) {
            got++;
            goto done;
        }
    }
    const int16_t *P = (const int16_t *)pt.buf;
    int64_t *B = (int64_t *)bd.buf;
    int ok;
    Py_BEGIN_ALLOW_THREADS
    ok = count_parts(P, n, K, B);
    if (ok)
        for (j = 0; j < m; j++)
            scatter_rows(P, n, B, cur, K, (const uint8_t *)sb[2 * j].buf, (uint8_t *)sb[2 * j + 1].buf, w[j]);
    Py_END_ALLOW_THREADS
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "partition_scatter: expected partitions in [0, K)");
        goto done;
    }
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (sb)
        for (j = 0; j < got; j++) {
            PyBuffer_Release(&sb[2 * j]);
            PyBuffer_Release(&sb[2 * j + 1]);
        }
    free(sb);
    free(w);
    free(cur);
    PyBuffer_Release(&pt);
    PyBuffer_Release(&bd);
    return ret;
}

/* partition_strings(part int16[n], K, offsets int32|int64[n+1], data, out_offsets (same width)[n+1], out_data,
 * wide): the strings of an Arrow array (its own offset applied by the caller) in the order partition_scatter gives
 * the rows; out_offsets start at 0, out_data holds offsets[n] - offsets[0] bytes.
 * twin: arr.take(np.argsort(part, kind="stable")) */
static PyObject *k_partition_strings(PyObject *self, PyObject *args) {
    Py_buffer pt, of, da, oo, od;
    Py_ssize_t K;
    int wide;
    if (!PyArg_ParseTuple(args, "y*ny*y*w*w*p", &pt, &K, &of, &da, &oo, &od, &wide)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = pt.len / 2, ow = wide ? 8 : 4;
    int64_t *rows = NULL, *bytes = NULL;
    if (K < 1 || K > 32767) {
        PyErr_SetString(PyExc_ValueError, "partition_strings: expected 1 <= K <= 32767");
        goto done;
    }
    if (!need(&pt, n, 2, "part") || !need(&of, n + 1, ow, "offsets") || !need(&oo, n + 1, ow, "out_offsets"))
        goto done;
    rows = calloc((size_t)(K + 1), sizeof(int64_t));
    bytes = calloc((size_t)(K + 1), sizeof(int64_t));
    if (!rows || !bytes) {
        PyErr_NoMemory();
        goto done;
    }
    const int16_t *P = (const int16_t *)pt.buf;
    const int32_t *O4 = (const int32_t *)of.buf;
    const int64_t *O8 = (const int64_t *)of.buf;
#define OFF(i) (wide ? O8[i] : (int64_t)O4[i])
    int64_t base = OFF(0);
    for (Py_ssize_t i = 0; i < n; i++)
        if (OFF(i + 1) < OFF(i) || OFF(i) < 0) {
            PyErr_SetString(PyExc_ValueError, "partition_strings: expected increasing offsets");
            goto done;
        }
    if (OFF(n) > da.len || OFF(n) - base != od.len) {
        PyErr_Format(PyExc_ValueError, "partition_strings: expected %lld data bytes, got %zd", (long long)(OFF(n) - base),
                     od.len);
        goto done;
    }
    int ok = 1;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n && ok; i++) {
        if (P[i] < 0 || P[i] >= K) {
            ok = 0;
            break;
        }
        rows[P[i] + 1]++;
        bytes[P[i] + 1] += OFF(i + 1) - OFF(i);
    }
    if (ok) {
        for (Py_ssize_t k = 1; k <= K; k++) {
            rows[k] += rows[k - 1];
            bytes[k] += bytes[k - 1];
        }
        const uint8_t *D = (const uint8_t *)da.buf;
        uint8_t *E = (uint8_t *)od.buf;
        for (Py_ssize_t i = 0; i < n; i++) {
            int64_t r = rows[P[i]]++, b = bytes[P[i]], len = OFF(i + 1) - OFF(i);
            if (wide)
                ((int64_t *)oo.buf)[r] = b;
            else
                ((int32_t *)oo.buf)[r] = (int32_t)b;
            memcpy(E + b, D + OFF(i), (size_t)len);
            bytes[P[i]] = b + len;
        }
        if (wide)
            ((int64_t *)oo.buf)[n] = OFF(n) - base;
        else
            ((int32_t *)oo.buf)[n] = (int32_t)(OFF(n) - base);
    }
    Py_END_ALLOW_THREADS
#undef OFF
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "partition_strings: expected partitions in [0, K)");
        goto done;
    }
    ret = Py_None;
    Py_INCREF(ret);
done:
    free(rows);
    free(bytes);
    PyBuffer_Release(&pt);
    PyBuffer_Release(&of);
    PyBuffer_Release(&da);
    PyBuffer_Release(&oo);
    PyBuffer_Release(&od);
    return ret;
}
/* ---- end of evaluate's key join ---- */

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
    {"hash_pairs", k_hash_pairs, METH_VARARGS,
     "hash_pairs(hg, hp, pos) -> bool: each GT hash's prediction row, or -1; False when a hash repeats on a side "
     "(twin: hpe_cli.pipelines.evaluate.spill.hash_matches)."},
    {"first_unequal", k_first_unequal, METH_VARARGS,
     "first_unequal(off_a, data_a, rows_a, off_b, data_b, rows_b, wide_a, wide_b) -> int: the first pair of "
     "strings that differ, or -1 (twin: pyarrow.compute.equal on the taken strings)."},
    {"partition_scatter", k_partition_scatter, METH_VARARGS,
     "partition_scatter(part, K, bounds, srcs, dsts, widths): rows in stable partition order (twin: a stable "
     "argsort of part and a take)."},
    {"partition_strings", k_partition_strings, METH_VARARGS,
     "partition_strings(part, K, offsets, data, out_offsets, out_data, wide): Arrow strings in stable partition "
     "order (twin: a stable argsort of part and a take)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_hpe_kernels",
                                    "hpe's optional compiled column kernels (csrc/_hpe_kernels.c).", -1, methods};

PyMODINIT_FUNC PyInit__hpe_kernels(void) { return PyModule_Create(&module); }
