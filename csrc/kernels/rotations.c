/* Rotations: sines and cosines, SciPy's and the systems' Euler splits, SciPy's quaternions, and the C library
 * functions the probes compare with numpy's. */
#include "kernels.h"

/* sin_cos(x float64[n], s float64[n], c float64[n]): s = sin(x), c = cos(x) by the C library's one call for both
 * (glibc's sincos: the same reduction and polynomials as its sin and cos, so the same bits; elsewhere sin and cos).
 * Transcendental: hpe_cli.native.sin_cos uses it only where it gives numpy's bits on a probe of values.
 * twin: np.sin(x), np.cos(x) */
PyObject *k_sin_cos(PyObject *self, PyObject *args) {
    Py_buffer x, s, c;
    if (!PyArg_ParseTuple(args, "y*w*w*", &x, &s, &c)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = x.len / 8;
    if (!need(&x, n, 8, "x") || !need(&s, n, 8, "sin") || !need(&c, n, 8, "cos")) goto done;
    const double *X = (const double *)x.buf;
    double *S = (double *)s.buf, *C = (double *)c.buf;
    Py_BEGIN_ALLOW_THREADS
#if defined(__GLIBC__)
    for (Py_ssize_t i = 0; i < n; i++) {
        /* into locals: with the arrays' addresses as outputs GCC 12 (-O3) made the call a sin and a cos call */
        double si, co;
        sincos(X[i], &si, &co);
        S[i] = si;
        C[i] = co;
    }
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

/* euler_from_matrix(R (9 float64[n] columns, row-major), out float64[n*3], i, j, k, sign, symmetric, intrinsic,
 * degrees, check) -> rows off orthonormal (then nothing is to be used: the twin projects them by SVD first)
 * SciPy's Rotation.from_matrix(R).as_euler(seq): Markley's matrix-to-quaternion (the case of the largest of the
 * diagonal and the trace, first on ties), then Bernardes and Viollet's angles (atan2 and hypot), the lock and the
 * wrap into [-pi, pi] as the twin does them, in its order. i, j, k, sign come from the twin's reading of seq.
 * twin: hpe_cli.metrics.scipy_columns.euler_from_matrix */
void quat_of_matrix(const double *r, double q[4]) {
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

PyObject *k_euler_from_matrix(PyObject *self, PyObject *args) {
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
    const double *r[9];
    if (!(have_r = nine(Ro, R, r, n, "R"))) goto done;
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
    if (have_r) release(R, 9);
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

PyObject *k_quat_matrix_from_euler(PyObject *self, PyObject *args) {
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

/* the angle d of a primary solution in the other solution: an outer turn by 180 degrees, the middle one to
 * 180 - d (-d for a proper sequence), lifted into (-180, 180]; numpy's where as a branch-free select */
static inline double other_angle(double d, int middle, int proper) {
    if (!middle) return lift((d + 180.0) - sel(d > 0, 360.0, 0.0));
    return proper ? lift(-d) : lift((180.0 - d) - sel(d < 0, 360.0, 0.0));
}

PyObject *k_system_angles(PyObject *self, PyObject *args) {
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
    const double *x[9];
    if (!(have_x = nine(Xo, X, x, n, "X"))) goto done;
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
        for (int r = 0; r < 3; r++) P2[r * n + t] = other_angle(P1[r * n + t], r == middle, proper);
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
PyObject *k_libm(PyObject *self, PyObject *args) {
    const char *name;
    PyObject *yo;
    Py_buffer x, y = {0}, o;
    if (!PyArg_ParseTuple(args, "sy*Ow*", &name, &x, &yo, &o)) return NULL;
    PyObject *ret = NULL;
    int have_y = 0;
    Py_ssize_t n = o.len / 8;
    if (!optional_buffer(yo, &y, PyBUF_SIMPLE, &have_y)) goto done;
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

/* second_solution(p1 (3 columns of n), middle, proper, p2 float64[3*n]): the other Euler solution of primary
 * angles in degrees: the outer turns by 180 degrees, the middle one to 180 - b (-b for a proper sequence), each
 * lifted into (-180, 180] (other_angle, as system_angles computes it).  twin: hpe_cli.rotation.solutions.second_degrees */
PyObject *k_second_solution(PyObject *self, PyObject *args) {
    PyObject *po;
    Py_buffer b2, P[3];
    int middle, proper;
    if (!PyArg_ParseTuple(args, "Oipw*", &po, &middle, &proper, &b2)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = b2.len / 24;
    int have_p = 0;
    if (!need(&b2, 3 * n, 8, "p2")) goto done;
    if (middle < 0 || middle > 2) {
        PyErr_SetString(PyExc_ValueError, "middle: expected 0, 1 or 2");
        goto done;
    }
    const double *p[3];
    if (!(have_p = columns(po, P, p, 3, n, "p1"))) goto done;
    double *P2 = (double *)b2.buf;
    Py_BEGIN_ALLOW_THREADS
    for (int r = 0; r < 3; r++) {
        const double *x = p[r];
        double *o = P2 + r * n;
        for (Py_ssize_t t = 0; t < n; t++) o[t] = other_angle(x[t], r == middle, proper);
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_p) release(P, 3);
    PyBuffer_Release(&b2);
    return ret;
}

