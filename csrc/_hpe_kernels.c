/* _hpe_kernels: hpe's optional compiled column kernels.
 *
 * Each function is one loop over a column where numpy takes a dozen passes or more, or a data-dependent loop
 * numpy cannot express (a hash over each string's bytes); each has a numpy twin in hpe_cli (named in its
 * docstring) that gives the same bits, and tests/native/ compares the two. The hashes and the screens compute
 * integers, fabs, differences and comparisons only. The error kernels add IEEE sums, products and square roots in
 * the order of their twins' numpy operations (the build passes -ffp-contract=off: no fused multiply-adds) and call
 * the C library's sincos, atan2, hypot, acos and asin, which hpe_cli.native uses only where they give numpy's bits
 * on a probe of values. The arguments are buffers (numpy arrays), checked for size; the GIL is released in the loops, so the
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
static int columns(PyObject *seq, Py_buffer *b, int count, Py_ssize_t n, const char *name) {
    PyObject *fast = PySequence_Fast(seq, "expected a sequence of columns");
    if (!fast) return 0;
    if (PySequence_Fast_GET_SIZE(fast) != count) {
        PyErr_Format(PyExc_ValueError, "%s: expected %d columns, got %zd", name, count, PySequence_Fast_GET_SIZE(fast));
        Py_DECREF(fast);
        return 0;
    }
    int k = 0;
    for (; k < count; k++) {
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(fast, k), &b[k], PyBUF_C_CONTIGUOUS) < 0) break;
        if (!need(&b[k], n, 8, name)) {
            k++;
            break;
        }
    }
    Py_DECREF(fast);
    if (k == count && !PyErr_Occurred()) return 1;
    for (int j = 0; j < k; j++) PyBuffer_Release(&b[j]);
    return 0;
}

static int nine(PyObject *seq, Py_buffer *b, Py_ssize_t n, const char *name) { return columns(seq, b, 9, n, name); }

static void release(Py_buffer *b, int count) {
    for (int k = 0; k < count; k++) PyBuffer_Release(&b[k]);
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

/* euler_from_matrix(R (9 float64[n] columns, row-major), out float64[n*3], i, j, k, sign, symmetric, intrinsic,
 * degrees, check) -> rows off orthonormal (then nothing is to be used: the twin projects them by SVD first)
 * SciPy's Rotation.from_matrix(R).as_euler(seq): Markley's matrix-to-quaternion (the case of the largest of the
 * diagonal and the trace, first on ties), then Bernardes and Viollet's angles (atan2 and hypot), the lock and the
 * wrap into [-pi, pi] as the twin does them, in its order. i, j, k, sign come from the twin's reading of seq.
 * twin: hpe_cli.metrics.scipy_columns.euler_from_matrix */
static inline void quat_of_matrix(const double *r, double q[4]) {
    double tr = r[0] + r[4] + r[8];
    int c0 = (r[0] >= r[4]) & (r[0] >= r[8]) & (r[0] >= tr);
    int c1 = !c0 & (r[4] >= r[8]) & (r[4] >= tr);
    int c2 = !(c0 | c1) & (r[8] >= tr);
    double d0 = r[7] - r[5], d1 = r[2] - r[6], d2 = r[3] - r[1];
    if (c0) q[0] = 1 - tr + 2 * r[0], q[1] = r[3] + r[1], q[2] = r[6] + r[2], q[3] = d0;
    else if (c1) q[0] = r[3] + r[1], q[1] = 1 - tr + 2 * r[4], q[2] = r[7] + r[5], q[3] = d1;
    else if (c2) q[0] = r[6] + r[2], q[1] = r[7] + r[5], q[2] = 1 - tr + 2 * r[8], q[3] = d2;
    else q[0] = d0, q[1] = d1, q[2] = d2, q[3] = 1 + tr;
    double norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int m = 0; m < 4; m++) q[m] = q[m] / norm;
}

static int orthonormal(const double *r) {
    for (int a = 0; a < 3; a++)
        for (int b = a; b < 3; b++) {
            double g = r[3 * a] * r[3 * b];
            g += r[3 * a + 1] * r[3 * b + 1];
            g += r[3 * a + 2] * r[3 * b + 2];
            if (a == b) g -= 1.0;
            if (!(fabs(g) <= (a == b ? 1e-12 + 1e-5 : 1e-12))) return 0;
        }
    return 1;
}

typedef struct {
    int i, j, k, symmetric, intrinsic;
    double sign;
} eseq_t;

static inline void euler_of_quat(const eseq_t *S, const double *q, double *o) {
    const double PI = 3.141592653589793, EPS = 1e-7;
    double qw = q[3], a, b, c, d;
    if (S->symmetric) a = qw, b = q[S->i], c = q[S->j], d = q[S->k] * S->sign;
    else a = qw - q[S->j], b = q[S->i] + q[S->k] * S->sign, c = q[S->j] + qw, d = q[S->k] * S->sign - q[S->i];
    double half_sum = atan2(b, a), half_diff = atan2(d, c);
    double mid = atan2(hypot(c, d), hypot(a, b));
    mid *= 2;
    int case1 = mid <= EPS, lock = case1 | (mid - PI >= -EPS);
    double first = half_sum - half_diff, third = half_sum + half_diff;
    if (lock) {
        double turn = case1 ? 2 * half_sum : 2 * half_diff * (S->intrinsic ? 1 : -1);
        if (S->intrinsic) first = 0.0, third = turn;
        else first = turn, third = 0.0;
    }
    if (!S->symmetric) {
        third *= S->sign;
        mid -= PI / 2;
    }
    double v[2] = {first, third};
    int col[2] = {S->intrinsic ? 2 : 0, S->intrinsic ? 0 : 2};
    for (int m = 0; m < 2; m++) {
        double x = v[m];
        if (x < -PI) x = x + 2 * PI;
        else if (x > PI) x = x - 2 * PI;
        o[col[m]] = x;
    }
    o[1] = mid;
}

static PyObject *k_euler_from_matrix(PyObject *self, PyObject *args) {
    PyObject *Ro;
    Py_buffer out, R[9];
    eseq_t S;
    int degrees, check;
    if (!PyArg_ParseTuple(args, "Ow*iiidpppp", &Ro, &out, &S.i, &S.j, &S.k, &S.sign, &S.symmetric, &S.intrinsic,
                          &degrees, &check))
        return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = out.len / 24, off = 0;
    int have_r = 0;
    if (!need(&out, 3 * n, 8, "out")) goto done;
    if (S.i < 0 || S.i > 2 || S.j < 0 || S.j > 2 || S.k < 0 || S.k > 2) {
        PyErr_SetString(PyExc_ValueError, "axes: expected 0, 1 or 2");
        goto done;
    }
    if (!(have_r = nine(Ro, R, n, "R"))) goto done;
    const double *r[9];
    for (int m = 0; m < 9; m++) r[m] = (const double *)R[m].buf;
    double *O = (double *)out.buf;
    const double DEG = 180.0 / 3.141592653589793;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double a[9], q[4];
        for (int m = 0; m < 9; m++) a[m] = r[m][i];
        if (check && !orthonormal(a)) {
            off++;
            continue;
        }
        quat_of_matrix(a, q);
        euler_of_quat(&S, q, O + 3 * i);
        if (degrees)
            for (int m = 0; m < 3; m++) O[3 * i + m] *= DEG;
    }
    Py_END_ALLOW_THREADS
    ret = PyLong_FromSsize_t(off);
done:
    if (have_r)
        for (int m = 0; m < 9; m++) PyBuffer_Release(&R[m]);
    PyBuffer_Release(&out);
    return ret;
}

/* quat_matrix_from_euler(angles float64[n*3], scale float64[3], sx, sy, sz (axes 0-2), intrinsic, q float64[4*n],
 * M float64[9*n]): SciPy's Rotation.from_euler(seq, angles * scale).as_quat() (each axis's elementary quaternion
 * of the half angle, composed in seq's order) and .as_matrix() of it, rows of q and M as columns (q[m*n + i]).
 * The degrees' factor is in scale (one product, as the twin's). Uses the C library's sincos.
 * twins: hpe_cli.metrics.scipy_columns.quat_from_euler, matrix_from_quat */
static inline void compose_q(const double *p, const double *q, double *o) {
    double cx = p[1] * q[2] - p[2] * q[1], cy = p[2] * q[0] - p[0] * q[2], cz = p[0] * q[1] - p[1] * q[0];
    o[0] = p[3] * q[0] + q[3] * p[0] + cx;
    o[1] = p[3] * q[1] + q[3] * p[1] + cy;
    o[2] = p[3] * q[2] + q[3] * p[2] + cz;
    o[3] = p[3] * q[3] - p[0] * q[0] - p[1] * q[1] - p[2] * q[2];
}

static PyObject *k_quat_matrix_from_euler(PyObject *self, PyObject *args) {
    Py_buffer ang, qo, mo;
    double sc[3];
    int ax[3], intrinsic;
    if (!PyArg_ParseTuple(args, "y*(ddd)(iii)pw*w*", &ang, &sc[0], &sc[1], &sc[2], &ax[0], &ax[1], &ax[2],
                          &intrinsic, &qo, &mo))
        return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = ang.len / 24;
    if (!need(&ang, 3 * n, 8, "angles") || !need(&qo, 4 * n, 8, "q") || !need(&mo, 9 * n, 8, "M")) goto done;
    for (int m = 0; m < 3; m++)
        if (ax[m] < 0 || ax[m] > 2) {
            PyErr_SetString(PyExc_ValueError, "axes: expected 0, 1 or 2");
            goto done;
        }
    const double *A = (const double *)ang.buf;
    double *Q = (double *)qo.buf, *M = (double *)mo.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double q[4], t[4];
        for (int m = 0; m < 3; m++) {
            double h = A[3 * i + m] * sc[m] / 2.0, s, c;
#if defined(__GLIBC__)
            sincos(h, &s, &c);
#else
            s = sin(h), c = cos(h);
#endif
            double e[4] = {0.0, 0.0, 0.0, c};
            e[ax[m]] = s;
            if (!m) memcpy(q, e, sizeof q);
            else {
                if (intrinsic) compose_q(q, e, t);
                else compose_q(e, q, t);
                memcpy(q, t, sizeof q);
            }
        }
        double x = q[0], y = q[1], z = q[2], w = q[3];
        double x2 = x * x, y2 = y * y, z2 = z * z, w2 = w * w;
        double xy = x * y, zw = z * w, xz = x * z, yw = y * w, yz = y * z, xw = x * w;
        double m9[9] = {x2 - y2 - z2 + w2, 2 * (xy - zw),      2 * (xz + yw),
                        2 * (xy + zw),      -x2 + y2 - z2 + w2, 2 * (yz - xw),
                        2 * (xz - yw),      2 * (yz + xw),      -x2 - y2 + z2 + w2};
        for (int m = 0; m < 4; m++) Q[m * n + i] = q[m];
        for (int m = 0; m < 9; m++) M[m * n + i] = m9[m];
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&ang);
    PyBuffer_Release(&qo);
    PyBuffer_Release(&mo);
    return ret;
}

/* wrapped_cos_errors(e1 float64[n*3], e2 float64[n*3], out float64[n*3], nan uint8[n]): opentrack's
 * arccos(cos a cos b + sin a sin b) per angle, the argument clipped to [-1, 1], in degrees; nan marks the rows
 * where one argument is past +-1 (NaN in the peer's unclipped code). Uses the C library's sincos and acos.
 * twin: hpe_cli.metrics.peer_angles.opentrack_errors */
static PyObject *k_wrapped_cos_errors(PyObject *self, PyObject *args) {
    Py_buffer e1, e2, out, nan;
    if (!PyArg_ParseTuple(args, "y*y*w*w*", &e1, &e2, &out, &nan)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = nan.len;
    if (!need(&e1, 3 * n, 8, "e1") || !need(&e2, 3 * n, 8, "e2") || !need(&out, 3 * n, 8, "out")) goto done;
    const double *a = (const double *)e1.buf, *b = (const double *)e2.buf;
    double *O = (double *)out.buf;
    uint8_t *NN = (uint8_t *)nan.buf;
    const double DEG = 180.0 / 3.141592653589793;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        int past = 0;
        for (int m = 0; m < 3; m++) {
            double s1, c1, s2, c2;
#if defined(__GLIBC__)
            sincos(a[3 * i + m], &s1, &c1);
            sincos(b[3 * i + m], &s2, &c2);
#else
            s1 = sin(a[3 * i + m]), c1 = cos(a[3 * i + m]), s2 = sin(b[3 * i + m]), c2 = cos(b[3 * i + m]);
#endif
            double dot = c1 * c2;
            dot += s1 * s2;
            past |= fabs(dot) > 1.0;
            dot = dot < -1.0 ? -1.0 : (dot > 1.0 ? 1.0 : dot);
            O[3 * i + m] = acos(dot) * DEG;
        }
        NN[i] = (uint8_t)past;
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&e1);
    PyBuffer_Release(&e2);
    PyBuffer_Release(&out);
    PyBuffer_Release(&nan);
    return ret;
}

/* c ? a : b without a branch (the data's signs are random: a branch would be mispredicted half the time) */
static inline double sel(int c, double a, double b) {
    uint64_t ua, ub, m = (uint64_t)0 - (uint64_t)(c != 0);
    memcpy(&ua, &a, 8);
    memcpy(&ub, &b, 8);
    ua = (ua & m) | (ub & ~m);
    memcpy(&a, &ua, 8);
    return a;
}

/* opal23_mae(a float64[n*3], p float64[n*3], out float64[n*3]): opal23's compute_mae of the annotation's and the
 * prediction's as_euler('XYZ') angles: the better (by mean) of the prediction and its other solution, each error
 * wrapped min(e, 360 - e); numpy's sign, where and minimum (NaN kept), in the twin's order.
 * twin: hpe_cli.metrics.peer_angles.opal23_mae */
static inline double np_sign(double x) { return sel(x > 0, 1.0, sel(x < 0, -1.0, sel(x == 0, 0.0, x))); }

static inline double np_minimum(double x, double y) { return sel(isnan(x) || x <= y, x, y); }

static PyObject *k_opal23_mae(PyObject *self, PyObject *args) {
    Py_buffer ab, pb, ob;
    if (!PyArg_ParseTuple(args, "y*y*w*", &ab, &pb, &ob)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = ob.len / 24;
    if (!need(&ab, 3 * n, 8, "a") || !need(&pb, 3 * n, 8, "p") || !need(&ob, 3 * n, 8, "out")) goto done;
    const double *A = (const double *)ab.buf, *P = (const double *)pb.buf;
    double *O = (double *)ob.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        static const int order[3] = {1, 0, 2}; /* the peer's (yaw, pitch, roll) */
        double pc[3], ac[3], w[3], e[3], ew[3];
        for (int k = 0; k < 3; k++) pc[k] = P[3 * i + order[k]], ac[k] = A[3 * i + order[k]];
        w[0] = 180 - pc[0];
        w[1] = pc[1] - np_sign(pc[1]) * 180;
        w[2] = pc[2] - np_sign(pc[2]) * 180;
        for (int k = 0; k < 3; k++) {
            w[k] = sel(w[k] > 180, w[k] - 360, w[k]);
            w[k] = sel(w[k] < -180, w[k] + 360, w[k]);
            e[k] = fabs(ac[k] - pc[k]);
            ew[k] = fabs(ac[k] - w[k]);
        }
        int use = (ew[0] + ew[1] + ew[2]) / 3 < (e[0] + e[1] + e[2]) / 3;
        for (int k = 0; k < 3; k++) {
            double x = sel(use, ew[k], e[k]);
            O[3 * i + order[k]] = np_minimum(x, 360 - x);
        }
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    PyBuffer_Release(&ab);
    PyBuffer_Release(&pb);
    PyBuffer_Release(&ob);
    return ret;
}

/* trace_acos_deg(A (9 columns), P (9 columns), out float64[n]): opal23's compute_ge,
 * degrees(arccos(clip((trace(A P^T) - 1) / 2, -1, 1))), the trace summed row by row as einsum does. Uses the C
 * library's acos. twin: hpe_cli.metrics.peer_angles.opal23_geodesic */
static PyObject *k_trace_acos_deg(PyObject *self, PyObject *args) {
    PyObject *Ao, *Po;
    Py_buffer ob, A[9], P[9];
    if (!PyArg_ParseTuple(args, "OOw*", &Ao, &Po, &ob)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = ob.len / 8;
    int have_a = 0, have_p = 0;
    if (!(have_a = nine(Ao, A, n, "A")) || !(have_p = nine(Po, P, n, "P"))) goto done;
    const double *a[9], *p[9];
    for (int k = 0; k < 9; k++) a[k] = (const double *)A[k].buf, p[k] = (const double *)P[k].buf;
    double *O = (double *)ob.buf;
    const double DEG = 180.0 / 3.141592653589793;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double t = a[0][i] * p[0][i];
        for (int k = 1; k < 9; k++) t = t + a[k][i] * p[k][i];
        double c = (t - 1) / 2;
        c = c < -1.0 ? -1.0 : (c > 1.0 ? 1.0 : c);
        O[i] = acos(c) * DEG;
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_a) release(A, 9);
    if (have_p) release(P, 9);
    PyBuffer_Release(&ob);
    return ret;
}

/* near_quats(P (9 columns), A (9 columns), q float64[n*4], near uint8[n]): the unit quaternions (x, y, z, w; rows)
 * of P A^T (SciPy's from_matrix, assume_valid) and whether each is within 90 degrees of the identity
 * (2 atan2(|(x, y, z)|, |w|) < pi / 2). Uses the C library's atan2.
 * twins: hpe_cli.metrics.peer_angles.opal23_near_quats (before its gather), opal23_near_mask */
static PyObject *k_near_quats(PyObject *self, PyObject *args) {
    PyObject *Po, *Ao;
    Py_buffer qb, nb, P[9], A[9];
    if (!PyArg_ParseTuple(args, "OOw*w*", &Po, &Ao, &qb, &nb)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = nb.len;
    int have_p = 0, have_a = 0;
    if (!need(&qb, 4 * n, 8, "q")) goto done;
    if (!(have_p = nine(Po, P, n, "P")) || !(have_a = nine(Ao, A, n, "A"))) goto done;
    const double *p[9], *a[9];
    for (int k = 0; k < 9; k++) p[k] = (const double *)P[k].buf, a[k] = (const double *)A[k].buf;
    double *Q = (double *)qb.buf;
    uint8_t *NR = (uint8_t *)nb.buf;
    const double HALF_PI = 3.141592653589793 / 2;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double m[9], *q = Q + 4 * i;
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++)
                m[3 * r + c] = p[3 * r][i] * a[3 * c][i] + p[3 * r + 1][i] * a[3 * c + 1][i] +
                               p[3 * r + 2][i] * a[3 * c + 2][i];
        quat_of_matrix(m, q);
        NR[i] = 2 * atan2(sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]), fabs(q[3])) < HALF_PI;
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_p) release(P, 9);
    if (have_a) release(A, 9);
    PyBuffer_Release(&qb);
    PyBuffer_Release(&nb);
    return ret;
}

/* quat_rotvecs(q (4 columns x, y, z, w of m rows), left float64[16], out float64[m*3]): SciPy's as_rotvec of
 * left @ q (each row's quaternion turned by a 4x4 matrix, the products summed left to right): the canonical sign
 * (w < 0, ties by x, y, z), the angle 2 atan2(|v|, |w|), the scale angle / sin(angle / 2) (its Taylor series at
 * or below 1e-3 rad). Uses the C library's atan2 and sin.
 * twin: hpe_cli.metrics.peer_angles' Karcher displacement (scipy_columns.rotvec_from_quat of the product) */
static PyObject *k_quat_rotvecs(PyObject *self, PyObject *args) {
    PyObject *qo;
    Py_buffer lb, ob, Qb[4];
    if (!PyArg_ParseTuple(args, "Oy*w*", &qo, &lb, &ob)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = ob.len / 24;
    int have_q = 0;
    if (!need(&ob, 3 * n, 8, "out") || !need(&lb, 16, 8, "left")) goto done;
    if (!(have_q = columns(qo, Qb, 4, n, "q"))) goto done;
    const double *q[4], *L = (const double *)lb.buf;
    for (int k = 0; k < 4; k++) q[k] = (const double *)Qb[k].buf;
    double *O = (double *)ob.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double r[4];
        for (int k = 0; k < 4; k++)
            r[k] = L[4 * k] * q[0][i] + L[4 * k + 1] * q[1][i] + L[4 * k + 2] * q[2][i] + L[4 * k + 3] * q[3][i];
        double x = r[0], y = r[1], z = r[2], w = r[3];
        int flip = w < 0;
        if (w == 0) flip |= (x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0))));
        double s = flip ? -1.0 : 1.0;
        double angle = 2 * atan2(sqrt(x * x + y * y + z * z), w * s);
        double a2 = angle * angle, scale;
        if (angle <= 1e-3) scale = 2 + a2 / 12 + 7 * a2 * a2 / 2880;
        else scale = angle / sin(angle / 2.0);
        scale = scale * s;
        O[3 * i] = scale * x, O[3 * i + 1] = scale * y, O[3 * i + 2] = scale * z;
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_q) release(Qb, 4);
    PyBuffer_Release(&lb);
    PyBuffer_Release(&ob);
    return ret;
}

/* system_angles(X (9 columns), p1 float64[3*n], p2 float64[3*n], lock float64[n], near uint8[n], i, j, k, proper,
 * e, scale (3), role (3), middle, refine_below) -> rows near the lock
 * A rotation system's two Euler solutions in degrees: solution 1 by the textbook atan2 formulas of the intrinsic
 * sequence (i, j, k; k is the third axis of a proper sequence's plane), each turn times its scale (+-180/pi by its
 * hand) and lifted from -180 to 180, placed at its role (p1's rows are pitch, yaw, roll); solution 2 from it (the
 * outer turns by 180 degrees, the middle one to 180 - b, or -b for a proper sequence, each into (-180, 180]). Rows
 * with lock below refine_below are marked in near: the twin solves their first angle from the residual, so the
 * caller recomputes them. Uses the C library's atan2.
 * twins: hpe_cli.rotation.euler.soa_to_euler, hpe_cli.rotation.system_def.RotationSystem.soa_to_angles */
static inline double lift(double d) { return sel(d <= -180.0, d + 360.0, d); }

static PyObject *k_system_angles(PyObject *self, PyObject *args) {
    PyObject *Xo;
    Py_buffer b1, b2, bl, bn, X[9];
    int i, j, k, proper, role[3], middle;
    double e, scale[3], refine;
    if (!PyArg_ParseTuple(args, "Ow*w*w*w*iiipd(ddd)(iii)id", &Xo, &b1, &b2, &bl, &bn, &i, &j, &k, &proper, &e,
                          &scale[0], &scale[1], &scale[2], &role[0], &role[1], &role[2], &middle, &refine))
        return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = bn.len, near = 0;
    int have_x = 0, ok = 1;
    if (!need(&b1, 3 * n, 8, "p1") || !need(&b2, 3 * n, 8, "p2") || !need(&bl, n, 8, "lock")) goto done;
    int idx[7] = {i, j, k, role[0], role[1], role[2], middle};
    for (int m = 0; m < 7; m++) ok &= idx[m] >= 0 && idx[m] <= 2;
    if (!ok || role[0] + role[1] + role[2] != 3 || role[0] == role[1]) {
        PyErr_SetString(PyExc_ValueError, "axes and roles: expected 0, 1 or 2, the roles each once");
        goto done;
    }
    if (!(have_x = nine(Xo, X, n, "X"))) goto done;
    const double *x[9];
    for (int m = 0; m < 9; m++) x[m] = (const double *)X[m].buf;
    double *P1 = (double *)b1.buf, *P2 = (double *)b2.buf, *L = (double *)bl.buf;
    uint8_t *NR = (uint8_t *)bn.buf;
#define E(r, c) x[3 * (r) + (c)][t]
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t t = 0; t < n; t++) {
        double v[3], lk;
        if (proper) { /* k is the plane's third axis m */
            lk = sqrt(E(i, j) * E(i, j) + E(i, k) * E(i, k));
            v[1] = atan2(lk, E(i, i));
            v[0] = atan2(E(j, i), -e * E(k, i));
            v[2] = atan2(E(i, j), e * E(i, k));
        } else {
            lk = sqrt(E(i, i) * E(i, i) + E(i, j) * E(i, j));
            if (e > 0) {
                v[1] = atan2(E(i, k), lk);
                v[0] = atan2(-E(j, k), E(k, k));
                v[2] = atan2(-E(i, j), E(i, i));
            } else {
                v[1] = atan2(-E(i, k), lk);
                v[0] = atan2(E(j, k), E(k, k));
                v[2] = atan2(E(i, j), E(i, i));
            }
        }
        L[t] = lk;
        NR[t] = lk < refine;
        near += lk < refine;
        for (int m = 0; m < 3; m++) P1[role[m] * n + t] = lift(v[m] * scale[m]);
        for (int r = 0; r < 3; r++) {
            double d = P1[r * n + t], d2;
            if (r != middle) d2 = (d + 180.0) - sel(d > 0, 360.0, 0.0);
            else if (proper) d2 = -d;
            else d2 = (180.0 - d) - sel(d < 0, 360.0, 0.0);
            P2[r * n + t] = lift(d2);
        }
    }
    Py_END_ALLOW_THREADS
#undef E
    ret = PyLong_FromSsize_t(near);
done:
    if (have_x) release(X, 9);
    PyBuffer_Release(&b1);
    PyBuffer_Release(&b2);
    PyBuffer_Release(&bl);
    PyBuffer_Release(&bn);
    return ret;
}

/* libm(name, x float64[n], y float64[n] or None, out float64[n]): the C library's atan2, hypot, acos or asin, for
 * hpe_cli.native's probes */
static PyObject *k_libm(PyObject *self, PyObject *args) {
    const char *name;
    PyObject *yo;
    Py_buffer x, y = {0}, o;
    if (!PyArg_ParseTuple(args, "sy*Ow*", &name, &x, &yo, &o)) return NULL;
    PyObject *ret = NULL;
    int have_y = 0;
    Py_ssize_t n = o.len / 8;
    if (yo != Py_None) {
        if (PyObject_GetBuffer(yo, &y, PyBUF_SIMPLE) < 0) goto done;
        have_y = 1;
    }
    if (!need(&x, n, 8, "x") || (have_y && !need(&y, n, 8, "y"))) goto done;
    const double *X = (const double *)x.buf, *Y = have_y ? (const double *)y.buf : NULL;
    double *O = (double *)o.buf;
    if (!strcmp(name, "atan2") && have_y)
        for (Py_ssize_t i = 0; i < n; i++) O[i] = atan2(X[i], Y[i]);
    else if (!strcmp(name, "hypot") && have_y)
        for (Py_ssize_t i = 0; i < n; i++) O[i] = hypot(X[i], Y[i]);
    else if (!strcmp(name, "acos") && !have_y)
        for (Py_ssize_t i = 0; i < n; i++) O[i] = acos(X[i]);
    else if (!strcmp(name, "asin") && !have_y)
        for (Py_ssize_t i = 0; i < n; i++) O[i] = asin(X[i]);
    else if (!strcmp(name, "sin") && !have_y)
        for (Py_ssize_t i = 0; i < n; i++) O[i] = sin(X[i]);
    else {
        PyErr_Format(PyExc_ValueError, "libm: expected atan2(x, y), hypot(x, y), acos(x), asin(x) or sin(x), got %s", name);
        goto done;
    }
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_y) PyBuffer_Release(&y);
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
    {"euler_from_matrix", k_euler_from_matrix, METH_VARARGS,
     "euler_from_matrix(R, out, i, j, k, sign, symmetric, intrinsic, degrees, check) -> rows off orthonormal: "
     "SciPy's as_euler of from_matrix (twin: hpe_cli.metrics.scipy_columns.euler_from_matrix)."},
    {"quat_matrix_from_euler", k_quat_matrix_from_euler, METH_VARARGS,
     "quat_matrix_from_euler(angles, scale, axes, intrinsic, q, M): SciPy's from_euler quaternions and their "
     "matrices (twins: hpe_cli.metrics.scipy_columns.quat_from_euler, matrix_from_quat)."},
    {"wrapped_cos_errors", k_wrapped_cos_errors, METH_VARARGS,
     "wrapped_cos_errors(e1, e2, out, nan): opentrack's angle errors (twin: "
     "hpe_cli.metrics.peer_angles.opentrack_errors)."},
    {"opal23_mae", k_opal23_mae, METH_VARARGS,
     "opal23_mae(a, p, out): opal23's compute_mae (twin: hpe_cli.metrics.peer_angles.opal23_mae)."},
    {"trace_acos_deg", k_trace_acos_deg, METH_VARARGS,
     "trace_acos_deg(A, P, out): opal23's compute_ge (twin: hpe_cli.metrics.peer_angles.opal23_geodesic)."},
    {"near_quats", k_near_quats, METH_VARARGS,
     "near_quats(P, A, q, near): quaternions of P A^T and their nearness (twin: "
     "hpe_cli.metrics.peer_angles.opal23_near_quats)."},
    {"quat_rotvecs", k_quat_rotvecs, METH_VARARGS,
     "quat_rotvecs(q, left, out): rotation vectors of left @ q (twin: hpe_cli.metrics.scipy_columns.rotvec_from_quat)."},
    {"system_angles", k_system_angles, METH_VARARGS,
     "system_angles(X, p1, p2, lock, near, i, j, k, proper, e, scale, role, middle, refine_below) -> rows near the "
     "lock: a system's two Euler solutions (twin: hpe_cli.rotation.system_def.RotationSystem.soa_to_angles)."},
    {"libm", k_libm, METH_VARARGS, "libm(name, x, y, out): the C library's atan2, hypot, acos, asin, sin (probes)."},
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
