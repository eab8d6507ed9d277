/* The audit's angle screen. */
#include "kernels.h"

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

PyObject *k_angle_screen(PyObject *self, PyObject *args) {
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
