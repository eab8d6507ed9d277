/* Evaluate's error formulas: the core metrics and the peers' own (opentrack, opal23). */
#include "kernels.h"

/* core_errors(P (9 float64[n] columns, row-major), G (9 columns), geo float64[n], maev float64[n*3], fro float64[n])
 * The geodesic angle of P G^T (atan2 of half its skew norm and half of trace - 1), the angle between each column of
 * P and of G (atan2 of the cross product's norm and the dot product) and ||P - G||_F, in degrees, in the order of
 * the numpy twins' operations (left to right; no fused multiply-adds). Uses the C library's atan2: hpe_cli.native
 * calls it only where atan2 gives numpy's bits on a probe.
 * twins: hpe_cli.metrics.rotation_errors.geodesic_deg, maev_deg, frobenius */
PyObject *k_core_errors(PyObject *self, PyObject *args) {
    PyObject *Po, *Go;
    Py_buffer geo, maev, fro, P[9], G[9];
    if (!PyArg_ParseTuple(args, "OOw*w*w*", &Po, &Go, &geo, &maev, &fro)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = geo.len / 8;
    int have_p = 0, have_g = 0;
    if (!need(&geo, n, 8, "geo") || !need(&maev, 3 * n, 8, "maev") || !need(&fro, n, 8, "fro")) goto done;
    const double *p[9], *g[9];
    if (!(have_p = nine(Po, P, p, n, "P")) || !(have_g = nine(Go, G, g, n, "G"))) goto done;
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
    if (have_p) release(P, 9);
    if (have_g) release(G, 9);
    PyBuffer_Release(&geo);
    PyBuffer_Release(&maev);
    PyBuffer_Release(&fro);
    return ret;
}

/* wrapped_cos_errors(e1 float64[n*3], e2 float64[n*3], out float64[n*3], nan uint8[n]): opentrack's
 * arccos(cos a cos b + sin a sin b) per angle, the argument clipped to [-1, 1], in degrees; nan marks the rows
 * where one argument is past +-1 (NaN in the peer's unclipped code). Uses the C library's sincos and acos.
 * twin: hpe_cli.metrics.peer_angles.opentrack_errors */
PyObject *k_wrapped_cos_errors(PyObject *self, PyObject *args) {
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

/* opal23_mae(a float64[n*3], p float64[n*3], out float64[n*3]): opal23's compute_mae of the annotation's and the
 * prediction's as_euler('XYZ') angles: the better (by mean) of the prediction and its other solution, each error
 * wrapped min(e, 360 - e); numpy's sign, where and minimum (NaN kept), in the twin's order.
 * twin: hpe_cli.metrics.peer_angles.opal23_mae */
static inline double np_sign(double x) { return sel(x > 0, 1.0, sel(x < 0, -1.0, sel(x == 0, 0.0, x))); }

static inline double np_minimum(double x, double y) { return sel(isnan(x) || x <= y, x, y); }

/* of two rows of absolute angle errors, the one with the smaller mean (the first on ties; the means summed left to
 * right, as numpy's), each kept error e as min(e, 360 - e); returns whether the second was kept. opal23's
 * compute_mae and hpe's best-of-two error both choose this way */
static inline int better_of_two(const double e1[3], const double e2[3], double out[3]) {
    int second = (e2[0] + e2[1] + e2[2]) / 3 < (e1[0] + e1[1] + e1[2]) / 3;
    for (int k = 0; k < 3; k++) {
        double e = sel(second, e2[k], e1[k]);
        out[k] = np_minimum(e, 360.0 - e);
    }
    return second;
}

PyObject *k_opal23_mae(PyObject *self, PyObject *args) {
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
        double pc[3], ac[3], w[3], e[3], ew[3], kept[3];
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
        better_of_two(e, ew, kept);
        for (int k = 0; k < 3; k++) O[3 * i + order[k]] = kept[k];
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
PyObject *k_trace_acos_deg(PyObject *self, PyObject *args) {
    PyObject *Ao, *Po;
    Py_buffer ob, A[9], P[9];
    if (!PyArg_ParseTuple(args, "OOw*", &Ao, &Po, &ob)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = ob.len / 8;
    int have_a = 0, have_p = 0;
    const double *a[9], *p[9];
    if (!(have_a = nine(Ao, A, a, n, "A")) || !(have_p = nine(Po, P, p, n, "P"))) goto done;
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
PyObject *k_near_quats(PyObject *self, PyObject *args) {
    PyObject *Po, *Ao;
    Py_buffer qb, nb, P[9], A[9];
    if (!PyArg_ParseTuple(args, "OOw*w*", &Po, &Ao, &qb, &nb)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = nb.len;
    int have_p = 0, have_a = 0;
    if (!need(&qb, 4 * n, 8, "q")) goto done;
    const double *p[9], *a[9];
    if (!(have_p = nine(Po, P, p, n, "P")) || !(have_a = nine(Ao, A, a, n, "A"))) goto done;
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
PyObject *k_quat_rotvecs(PyObject *self, PyObject *args) {
    PyObject *qo;
    Py_buffer lb, ob, Qb[4];
    if (!PyArg_ParseTuple(args, "Oy*w*", &qo, &lb, &ob)) return NULL;
    PyObject *ret = NULL;
    Py_ssize_t n = ob.len / 24;
    int have_q = 0;
    if (!need(&ob, 3 * n, 8, "out") || !need(&lb, 16, 8, "left")) goto done;
    const double *q[4], *L = (const double *)lb.buf;
    if (!(have_q = columns(qo, Qb, q, 4, n, "q"))) goto done;
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

/* best_of_two(p1 float64[n*3], p2 float64[n*3], g float64[n*3], best float64[n*3], second uint8[n], wrapped
 * float64[n*3] or None): hpe's core angle errors of the prediction's two solutions against the ground truth: the
 * solution whose mean |difference| is smaller (the first on ties), each kept error e as min(e, 360 - e); and, when
 * wrapped is given, min(e, 360 - e) of e = |p1 - g| mod 360 (the wrapped error). numpy's abs, where, remainder and
 * minimum (NaN kept), in the twins' order; no C library function but fmod (exact).
 * twins: hpe_cli.metrics.rotation_errors.best_of_two_error, wrapped_error */
PyObject *k_best_of_two(PyObject *self, PyObject *args) {
    Py_buffer b1, b2, bg, bb, bs, bw = {0};
    PyObject *wo;
    if (!PyArg_ParseTuple(args, "y*y*y*w*w*O", &b1, &b2, &bg, &bb, &bs, &wo)) return NULL;
    PyObject *ret = NULL;
    int have_w = 0;
    Py_ssize_t n = bs.len;
    if (!optional_buffer(wo, &bw, PyBUF_WRITABLE, &have_w)) goto done;
    if (!need(&b1, 3 * n, 8, "p1") || !need(&b2, 3 * n, 8, "p2") || !need(&bg, 3 * n, 8, "g") ||
        !need(&bb, 3 * n, 8, "best") || (have_w && !need(&bw, 3 * n, 8, "wrapped")))
        goto done;
    const double *P1 = (const double *)b1.buf, *P2 = (const double *)b2.buf, *G = (const double *)bg.buf;
    double *B = (double *)bb.buf, *W = have_w ? (double *)bw.buf : NULL;
    uint8_t *S = (uint8_t *)bs.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        double e1[3], e2[3];
        for (int k = 0; k < 3; k++) e1[k] = fabs(P1[3 * i + k] - G[3 * i + k]), e2[k] = fabs(P2[3 * i + k] - G[3 * i + k]);
        S[i] = (uint8_t)better_of_two(e1, e2, B + 3 * i);
        if (W)
            for (int k = 0; k < 3; k++) {
                double e = e1[k]; /* |p1 - g|, as wrap_abs_deg takes it */
                if (!(e < 360.0)) { /* numpy's remainder by 360 (only needed from 360 up, or NaN) */
                    double m = fmod(e, 360.0);
                    e = m == 0.0 ? 0.0 : m;
                }
                W[3 * i + k] = np_minimum(e, 360.0 - e);
            }
    }
    Py_END_ALLOW_THREADS
    ret = Py_None;
    Py_INCREF(ret);
done:
    if (have_w) PyBuffer_Release(&bw);
    PyBuffer_Release(&b1);
    PyBuffer_Release(&b2);
    PyBuffer_Release(&bg);
    PyBuffer_Release(&bb);
    PyBuffer_Release(&bs);
    return ret;
}

