"""What the C library's math functions cost ``hpe evaluate``'s default run, and what faster ones would change.

    python benchmarks/libm.py [--rows 65536] [--seed 0] [--samples 20000] [--run PRED GT [--sites] [--drop-in]]

Each measurement runs in a child process, built here with the system's C compiler where it needs one (Linux with
glibc; a part that cannot be built or run says so and is skipped):

* calls per pair: a shim preloaded with ``LD_PRELOAD`` counts every call to ``atan2``, ``hypot``, ``acos``,
  ``asin``, ``sin``, ``cos``, ``sincos`` and ``acosf`` (numpy's, SciPy's and hpe's kernels' alike) while
  :func:`hpe_cli.metrics.evaluate.compute_rows` scores one chunk of ``--rows`` pairs with every protocol but
  ``opal23-align`` (whose rows are scored after the pass), as ``hpe evaluate`` does: 300w_lp ground truth and
  6drepnet predictions turned by about 5 degrees.
* cost per call: a bare C loop over 4M random arguments calls glibc's scalar functions (the ones numpy and
  SciPy call, whose results the peers' evaluation code prints) and glibc's AVX2 vector versions (``libmvec``,
  ``_ZGVdN4...``); it prints both times, the share of results that differ and the largest difference in units
  in the last place.
* rounding: how often numpy's ``arctan2``, ``hypot``, ``arccos`` and ``sin`` here (glibc's, unless numpy was
  built for and runs on an AVX512_SKX CPU, where it calls Intel's SVML instead) differ from the correctly rounded
  result (mpmath at 200 bits, skipped without mpmath), and by how much: no other implementation gives their bits
  in every row unless it copies their code. Then a nearly correctly rounded AVX2 ``atan2`` written here, against
  glibc's: alone (its time, and the results that differ from glibc's), and behind a rounding test that keeps
  glibc's bits by calling glibc wherever the result is within glibc's own error of a rounding boundary.
* ``--run PRED GT``: a whole ``hpe evaluate PRED GT`` run (every protocol; 6drepnet predictions, 300w_lp ground
  truth, as ``benchmarks/evaluate.py`` writes them) under the shim: its calls per pair, labels and opal23-align's
  second pass included, times each function's scalar cost measured here: the C library's floor for that run,
  in CPU seconds and in wall seconds on this machine's cores, beside the run's own time (the shim's counting
  adds a little to it).

  With ``--sites``, the same run's calls per pair by the function that made them (a kernel by name, or numpy):
  which of them are SciPy's own (the kernels that repeat SciPy's ``Rotation``: ``euler_of_quat``,
  ``k_quat_matrix_from_euler``), which a numpy-based peer's or hpe's own.
  With ``--drop-in``, the same run (no shim) is also timed with a preloaded ``atan2`` about twice as fast as
  glibc's (a 65-entry table and a short series; within a few units in the last place) and ``hypot`` as
  ``sqrt(x * x + y * y)``: what faster scalar functions, called where hpe calls them, would save.

hpe reproduces each peer's numbers to the last bit, so it calls the scalar functions; the tables say what the
vector ones would save and what they would change.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

FUNCS = ("atan2", "hypot", "acos", "asin", "sin", "cos", "sincos", "acosf")

# the counting shim: each wrapper counts, then calls the next definition (glibc's)
SHIM = (
    "#define _GNU_SOURCE\n#include <dlfcn.h>\n#include <stdatomic.h>\n"
    "static atomic_long n_[8];\n"
    "#define W1(f,i) static double (*r_##f)(double); double f(double x)"
    "{ if(!r_##f) r_##f=dlsym(RTLD_NEXT,#f); atomic_fetch_add(&n_[i],1); return r_##f(x);}\n"
    "#define W2(f,i) static double (*r_##f)(double,double); double f(double x,double y)"
    "{ if(!r_##f) r_##f=dlsym(RTLD_NEXT,#f); atomic_fetch_add(&n_[i],1); return r_##f(x,y);}\n"
    "W2(atan2,0) W2(hypot,1) W1(acos,2) W1(asin,3) W1(sin,4) W1(cos,5)\n"
    "static void (*r_sc)(double,double*,double*);\n"
    'void sincos(double x,double*s,double*c){ if(!r_sc) r_sc=dlsym(RTLD_NEXT,"sincos");'
    " atomic_fetch_add(&n_[6],1); r_sc(x,s,c);}\n"
    "static float (*r_af)(float);\n"
    'float acosf(float x){ if(!r_af) r_af=dlsym(RTLD_NEXT,"acosf"); atomic_fetch_add(&n_[7],1); return r_af(x);}\n'
    "void hpe_count_reset(void){ for(int i=0;i<8;i++) n_[i]=0; }\n"
    "long hpe_count(int i){ return n_[i]; }\n"
)

# scalar against vector, the same arguments
LOOPS = textwrap.dedent(
    """
    #define _GNU_SOURCE
    #include <stdio.h>
    #include <stdlib.h>
    #include <math.h>
    #include <time.h>
    #include <immintrin.h>
    __m256d _ZGVdN4vv_atan2(__m256d, __m256d);
    __m256d _ZGVdN4vv_hypot(__m256d, __m256d);
    __m256d _ZGVdN4v_acos(__m256d);
    __m256d _ZGVdN4v_sin(__m256d);
    static double now(void) { struct timespec a; clock_gettime(CLOCK_MONOTONIC, &a); return a.tv_sec * 1e9 + a.tv_nsec; }
    static void report(const char *name, const double *s, const double *v, int n, double ts, double tv) {
        long diff = 0; double worst = 0;
        for (int i = 0; i < n; i++) if (s[i] != v[i]) {
            diff++;
            double u = fabs(s[i] - v[i]) / (nextafter(fabs(s[i]), INFINITY) - fabs(s[i]));
            if (u > worst) worst = u;
        }
        printf("%s %.2f %.2f %.2f %.1f\\n", name, ts, tv, 100.0 * diff / n, worst);
    }
    int main(void) {
        int n = 1 << 22;
        double *x = aligned_alloc(32, 8 * n), *y = aligned_alloc(32, 8 * n);
        double *s = aligned_alloc(32, 8 * n), *v = aligned_alloc(32, 8 * n);
        srand(1);
        for (int i = 0; i < n; i++) { x[i] = rand() / (double)RAND_MAX * 2 - 1; y[i] = rand() / (double)RAND_MAX * 2 - 1; }
        for (int i = 0; i < n; i++) s[i] = v[i] = 0;  /* pages faulted before timing */
        double t, ts, tv;
    #define RUN(NAME, SCALAR, VECTOR) \\
        t = now(); for (int i = 0; i < n; i++) s[i] = SCALAR; ts = (now() - t) / n; \\
        t = now(); for (int i = 0; i < n; i += 4) { __m256d X = _mm256_load_pd(x + i), Y = _mm256_load_pd(y + i); \\
                                                    _mm256_store_pd(v + i, VECTOR); } tv = (now() - t) / n; \\
        report(NAME, s, v, n, ts, tv);
        RUN("atan2", atan2(y[i], x[i]), _ZGVdN4vv_atan2(Y, X))
        RUN("hypot", hypot(y[i], x[i]), _ZGVdN4vv_hypot(Y, X))
        RUN("acos", acos(x[i]), _ZGVdN4v_acos(X))
        RUN("sin", sin(3 * x[i]), _ZGVdN4v_sin(_mm256_mul_pd(X, _mm256_set1_pd(3.0))))
        return 0;
    }
    """
)

# each function's scalar cost, the arguments in its usual range (no vector unit needed)
COSTS = textwrap.dedent(
    """
    #define _GNU_SOURCE
    #include <stdio.h>
    #include <stdlib.h>
    #include <math.h>
    #include <time.h>
    static double now(void) { struct timespec a; clock_gettime(CLOCK_MONOTONIC, &a); return a.tv_sec * 1e9 + a.tv_nsec; }
    int main(void) {
        int n = 1 << 21;
        double *x = malloc(8 * n), *y = malloc(8 * n), *o = malloc(8 * n), *p = malloc(8 * n), acc = 0, t;
        float *f = malloc(4 * n), *g = malloc(4 * n);
        srand(1);
        for (int i = 0; i < n; i++) {
            x[i] = rand() / (double)RAND_MAX * 2 - 1; y[i] = rand() / (double)RAND_MAX * 2 - 1;
            f[i] = (float)x[i]; o[i] = p[i] = g[i] = 0;
        }
    #define COST(NAME, BODY) t = now(); for (int i = 0; i < n; i++) { BODY; } \
        printf("%s %.3f\\n", NAME, (now() - t) / n); acc += o[n / 2] + p[n / 3] + g[n / 5];
        COST("atan2", o[i] = atan2(y[i], x[i]))
        COST("hypot", o[i] = hypot(y[i], x[i]))
        COST("acos", o[i] = acos(x[i]))
        COST("asin", o[i] = asin(x[i]))
        COST("sin", o[i] = sin(3 * x[i]))
        COST("cos", o[i] = cos(3 * x[i]))
        COST("sincos", sincos(3 * x[i], o + i, p + i))
        COST("acosf", g[i] = acosf(f[i]))
        return acc > 1e300;
    }
    """
)

# faster scalar atan2 and hypot, preloaded in place of glibc's for --drop-in (not exact: a timing experiment)
DROP_IN = textwrap.dedent(
    """
    #define _GNU_SOURCE
    #include <dlfcn.h>
    #include <math.h>
    static double T[65];
    static double (*r_atan2)(double, double);
    __attribute__((constructor)) static void setup(void) {
        double (*ra)(double) = dlsym(RTLD_NEXT, "atan");
        r_atan2 = dlsym(RTLD_NEXT, "atan2");
        for (int j = 0; j < 65; j++) T[j] = ra(j / 64.0);
    }
    double atan2(double y, double x) {
        double ax = fabs(x), ay = fabs(y);
        if (!(ax > 0x1p-500 && ay > 0x1p-500 && ax < 0x1p500 && ay < 0x1p500)) return r_atan2(y, x);
        int sw = ay > ax;
        double a = sw ? ax / ay : ay / ax;
        int j = (int)(a * 64 + 0.5);
        double c = j / 64.0, u = (a - c) / (1 + a * c), u2 = u * u;
        double r = T[j] + (u - u * u2 * (1.0 / 3 - u2 * (1.0 / 5 - u2 / 7)));
        if (sw) r = 1.5707963267948966 - r;
        if (x < 0) r = 3.141592653589793 - r;
        return copysign(r, y);
    }
    double hypot(double x, double y) { return sqrt(x * x + y * y); }
    """
)

# the child that measures numpy's functions against mpmath's correctly rounded results
ROUNDING_CHILD = textwrap.dedent(
    """
    import sys
    import mpmath
    import numpy as np
    mpmath.mp.prec = 200
    n = int(sys.argv[1])
    rng = np.random.default_rng(1)
    y, x = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    cases = {
        "atan2": (np.arctan2(y, x), lambda i: mpmath.atan2(y[i], x[i])),
        "hypot": (np.hypot(y, x), lambda i: mpmath.hypot(y[i], x[i])),
        "acos": (np.arccos(x), lambda i: mpmath.acos(x[i])),
        "sin": (np.sin(3 * x), lambda i: mpmath.sin(3 * x[i])),
    }
    for name, (got, exact) in cases.items():
        off, worst = 0, 0.0
        for i in range(n):
            g = float(got[i])
            err = abs(float((mpmath.mpf(g) - exact(i)) / np.spacing(abs(g))))
            off += err > 0.5
            worst = max(worst, err)
        print(name, 100.0 * off / n, worst)
    """
)

# a nearly correctly rounded AVX2 atan2 (double-double from a 65-entry table; the table is filled in by vector_atan2),
# timed against glibc's, alone and behind a rounding test that falls back to glibc where the result is within
# MARGIN units in the last place of a rounding boundary (the only way to keep glibc's bits: its own error)
VECTOR_ATAN2 = textwrap.dedent(
    """
    #include <immintrin.h>
    #include <math.h>
    #include <stdint.h>
    #include <stdio.h>
    #include <stdlib.h>
    #include <string.h>
    #include <time.h>
    static const double T_HI[65] = {TABLE_HI}, T_LO[65] = {TABLE_LO};
    #define V __m256d
    #define TWO_SUM(a, b, s, e) do { s = _mm256_add_pd(a, b); V bb_ = _mm256_sub_pd(s, a); \\
        e = _mm256_add_pd(_mm256_sub_pd(a, _mm256_sub_pd(s, bb_)), _mm256_sub_pd(b, bb_)); } while (0)
    static V C(double x) { return _mm256_set1_pd(x); }
    /* atan2(y, x) as S + L, |error| about 2^-64 |S|; good: the lanes computed (both in [2^-500, 2^500]) */
    static V atan2_dd(V y, V x, V *L_out, V *good) {
        V sign = _mm256_castsi256_pd(_mm256_set1_epi64x(0x8000000000000000LL));
        V ax = _mm256_andnot_pd(sign, x), ay = _mm256_andnot_pd(sign, y);
        V swap = _mm256_cmp_pd(ay, ax, _CMP_GT_OQ), a = _mm256_min_pd(ax, ay), b = _mm256_max_pd(ax, ay);
        *good = _mm256_and_pd(_mm256_cmp_pd(a, C(0x1p-500), _CMP_GE_OQ), _mm256_cmp_pd(b, C(0x1p500), _CMP_LE_OQ));
        a = _mm256_blendv_pd(C(0.5), a, *good); b = _mm256_blendv_pd(C(1.0), b, *good);
        V ib = _mm256_div_pd(C(1.0), b), th = _mm256_mul_pd(a, ib);
        V tl = _mm256_mul_pd(_mm256_fnmadd_pd(th, b, a), ib);
        V jd = _mm256_round_pd(_mm256_mul_pd(th, C(64.0)), _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
        __m128i j = _mm256_cvtpd_epi32(jd);
        V c = _mm256_mul_pd(jd, C(1.0 / 64)), num = _mm256_sub_pd(th, c);  /* exact */
        V p = _mm256_mul_pd(th, c), pe = _mm256_fmsub_pd(th, c, p), s = _mm256_add_pd(C(1.0), p);
        V dl = _mm256_fmadd_pd(tl, c, _mm256_add_pd(_mm256_add_pd(_mm256_sub_pd(C(1.0), s), p), pe));
        V is = _mm256_div_pd(C(1.0), s), uh = _mm256_mul_pd(num, is);
        V ul = _mm256_mul_pd(_mm256_fnmadd_pd(uh, dl, _mm256_add_pd(_mm256_fnmadd_pd(uh, s, num), tl)), is);
        V u2 = _mm256_mul_pd(uh, uh), P = _mm256_fmadd_pd(u2, C(-1.0 / 11), C(1.0 / 9));
        P = _mm256_fmadd_pd(u2, P, C(-1.0 / 7)); P = _mm256_fmadd_pd(u2, P, C(1.0 / 5));
        P = _mm256_fmadd_pd(u2, P, C(-1.0 / 3)); P = _mm256_mul_pd(_mm256_mul_pd(u2, P), uh);
        V S, E, S2, E2;
        TWO_SUM(_mm256_i32gather_pd(T_HI, j, 8), uh, S, E);
        V L = _mm256_add_pd(_mm256_add_pd(E, _mm256_i32gather_pd(T_LO, j, 8)), _mm256_add_pd(ul, P));
        TWO_SUM(C(0x1.921fb54442d18p+0), _mm256_xor_pd(S, sign), S2, E2);  /* pi/2 - (S + L) */
        V L2 = _mm256_sub_pd(_mm256_add_pd(E2, C(0x1.1a62633145c07p-54)), L);
        S = _mm256_blendv_pd(S, S2, swap); L = _mm256_blendv_pd(L, L2, swap);
        V neg = _mm256_cmp_pd(x, _mm256_setzero_pd(), _CMP_LT_OQ);
        TWO_SUM(C(0x1.921fb54442d18p+1), _mm256_xor_pd(S, sign), S2, E2);  /* pi - (S + L) */
        L2 = _mm256_sub_pd(_mm256_add_pd(E2, C(0x1.1a62633145c07p-53)), L);
        S = _mm256_blendv_pd(S, S2, neg); L = _mm256_blendv_pd(L, L2, neg);
        V ys = _mm256_and_pd(y, sign);
        *L_out = _mm256_xor_pd(L, ys);
        return _mm256_xor_pd(S, ys);
    }
    static long fallbacks;
    static void run(const double *Y, const double *X, double *O, long n, double margin) {
        V expo = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7ff0000000000000LL));
        for (long i = 0; i < n; i += 4) {
            V L, good, S = atan2_dd(_mm256_loadu_pd(Y + i), _mm256_loadu_pd(X + i), &L, &good);
            _mm256_storeu_pd(O + i, _mm256_add_pd(S, L));
            if (margin <= 0) continue;
            V e = _mm256_mul_pd(_mm256_and_pd(S, expo), C(margin * 0x1p-52));
            V ok = _mm256_and_pd(good, _mm256_cmp_pd(_mm256_add_pd(S, _mm256_add_pd(L, e)),
                                                    _mm256_add_pd(S, _mm256_sub_pd(L, e)), _CMP_EQ_OQ));
            int m = _mm256_movemask_pd(ok);
            if (m != 15)
                for (int l = 0; l < 4; l++)
                    if (!(m >> l & 1)) { O[i + l] = atan2(Y[i + l], X[i + l]); fallbacks++; }
        }
    }
    static double now(void) { struct timespec a; clock_gettime(CLOCK_MONOTONIC, &a); return a.tv_sec * 1e9 + a.tv_nsec; }
    int main(void) {
        long n = 1 << 22;
        double *y = aligned_alloc(32, 8 * n), *x = aligned_alloc(32, 8 * n), *g = aligned_alloc(32, 8 * n);
        double *o = aligned_alloc(32, 8 * n);
        srand(1);
        for (long i = 0; i < n; i++) { x[i] = rand() / (double)RAND_MAX * 2 - 1; y[i] = rand() / (double)RAND_MAX * 2 - 1; }
        memset(g, 0, 8 * n); memset(o, 0, 8 * n);
        double t = now(); for (long i = 0; i < n; i++) g[i] = atan2(y[i], x[i]); double tg = (now() - t) / n;
        for (int k = 0; k < 2; k++) {
            double margin = k ? 0.0625 : 0.0;
            fallbacks = 0; t = now(); run(y, x, o, n, margin); double tv = (now() - t) / n;
            long diff = 0; for (long i = 0; i < n; i++) diff += memcmp(o + i, g + i, 8) != 0;
            printf("%g %.2f %.2f %.4f %.2f\\n", margin, tg, tv, 100.0 * diff / n, 100.0 * fallbacks / n);
        }
        return 0;
    }
    """
)


# the child that runs one command under the shim, in process (the CLI leaves with os._exit), then writes the counts
RUN_CHILD = textwrap.dedent(
    """
    import ctypes, sys
    from hpe_cli.cli.main import cli
    lib = ctypes.CDLL(sys.argv[1])
    lib.hpe_count.restype = ctypes.c_long
    cli(args=sys.argv[3:], standalone_mode=False)
    with open(sys.argv[2], "w") as f:
        f.write(" ".join(str(lib.hpe_count(i)) for i in range(8)))
    """
)

# the shim of --sites: each call counted by its return address (the calling function, resolved with addr2line)
SITES_SHIM = textwrap.dedent(
    """
    #define _GNU_SOURCE
    #include <dlfcn.h>
    #include <pthread.h>
    #include <stdint.h>
    #include <stdio.h>
    #define NS 4096
    static void *ra_[NS];
    static long long n_[NS][5];
    static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    static void add(void *ra, int f) {
        uintptr_t h = ((uintptr_t)ra * 0x9E3779B97F4A7C15ULL) >> 52;
        pthread_mutex_lock(&mu);
        for (;; h = (h + 1) & (NS - 1)) {
            if (!ra_[h]) ra_[h] = ra;
            if (ra_[h] == ra) { n_[h][f]++; break; }
        }
        pthread_mutex_unlock(&mu);
    }
    #define W1(f, i) static double (*r_##f)(double); \\
        double f(double x) { if (!r_##f) r_##f = dlsym(RTLD_NEXT, #f); add(__builtin_return_address(0), i); return r_##f(x); }
    #define W2(f, i) static double (*r_##f)(double, double); \\
        double f(double x, double y) { if (!r_##f) r_##f = dlsym(RTLD_NEXT, #f); add(__builtin_return_address(0), i); \\
                                       return r_##f(x, y); }
    W2(atan2, 0) W2(hypot, 1) W1(acos, 2) W1(asin, 3)
    static void (*r_sc)(double, double *, double *);
    void sincos(double x, double *s, double *c) {
        if (!r_sc) r_sc = dlsym(RTLD_NEXT, "sincos");
        add(__builtin_return_address(0), 4);
        r_sc(x, s, c);
    }
    void hpe_sites_write(const char *path) {
        FILE *f = fopen(path, "w");
        for (int i = 0; f && i < NS; i++) {
            Dl_info d;
            if (!ra_[i] || !dladdr(ra_[i], &d)) continue;
            fprintf(f, "%s 0x%lx %lld %lld %lld %lld %lld\\n", d.dli_fname ? d.dli_fname : "?",
                    (unsigned long)((char *)ra_[i] - (char *)d.dli_fbase), n_[i][0], n_[i][1], n_[i][2], n_[i][3], n_[i][4]);
        }
        if (f) fclose(f);
    }
    """
)
SITE_FUNCS = ("atan2", "hypot", "acos", "asin", "sincos")

# the child of --sites: one command under the sites shim, then the table written
SITES_CHILD = textwrap.dedent(
    """
    import ctypes, sys
    from hpe_cli.cli.main import cli
    lib = ctypes.CDLL(sys.argv[1])
    cli(args=sys.argv[3:], standalone_mode=False)
    lib.hpe_sites_write(sys.argv[2].encode())
    """
)

# the child that scores one chunk under the shim
CHILD = textwrap.dedent(
    """
    import ctypes, sys
    import numpy as np
    from hpe_cli.metrics.evaluate import compute_rows
    from hpe_cli.metrics.protocols import PROTOCOLS
    from hpe_cli.pipelines.evaluate.opal23 import opal23_chunk
    from hpe_cli.pipelines.evaluate.sides import stored_of_angles
    from hpe_cli.rotation.systems import get_system

    n, seed, shim = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    lib = ctypes.CDLL(shim)
    lib.hpe_count.restype = ctypes.c_long
    rng = np.random.default_rng(seed)
    gt = np.column_stack([rng.uniform(-60, 60, n), rng.uniform(-85, 85, n), rng.uniform(-45, 45, n)])
    pred = gt + rng.normal(0, 3, (n, 3))
    ps, gs = get_system("6drepnet"), get_system("300w_lp")
    def labels():  # as evaluate's readers build both sides' matrices from their angles
        return ps.soa_to_canonical(stored_of_angles(ps, pred)), gs.soa_to_canonical(stored_of_angles(gs, gt))
    def counted(job):
        job()  # warm: probes, caches
        lib.hpe_count_reset()
        out = job()
        return out, " ".join(str(lib.hpe_count(i) / n) for i in range(8))
    (P, G), label_calls = counted(labels)
    raw = {"pred": ("6drepnet", pred), "gt": ("300w_lp", gt)}
    names = [p for p in PROTOCOLS if p != "opal23-align"]
    _, scoring_calls = counted(lambda: compute_rows(P, G, gs, names, raw, {}, opal23_chunk))
    print(scoring_calls)
    print(label_calls)
    """
)


def _compile(cc: str, src: str, out: Path, *flags: str) -> str | None:
    """Compile ``src`` to ``out``; None when it built, else the compiler's first error line."""
    c = out.with_suffix(".c")
    c.write_text(src)
    r = subprocess.run([cc, "-O2", *flags, "-o", str(out), str(c), "-lm"], capture_output=True, text=True)
    if r.returncode:
        lines = [ln for ln in r.stderr.splitlines() if "error" in ln] or r.stderr.splitlines() or ["failed"]
        return lines[0]
    return None


def _shim(cc: str, tmp: Path):
    """``(path of the counting shim, None)``, built once in ``tmp``, or ``(path, the compiler's error)``."""
    shim = tmp / "libcount.so"
    return shim, (None if shim.exists() else _compile(cc, SHIM, shim, "-shared", "-fPIC", "-ldl"))


def count_calls(cc: str, tmp: Path, rows: int, seed: int = 0):
    """``{"scoring": {function: calls per pair}, "labels": {...}}``: one chunk scored with every protocol but
    opal23-align, and both sides' matrices built from their angles; or the reason they could not be counted (a
    string)."""
    shim, err = _shim(cc, tmp)
    if err:
        return f"the counting shim did not build: {err}"
    env = dict(os.environ, LD_PRELOAD=str(shim))
    r = subprocess.run(
        [sys.executable, "-c", CHILD, str(rows), str(seed), str(shim)], env=env, capture_output=True, text=True
    )
    if r.returncode:
        return f"the child failed: {(r.stderr.strip().splitlines() or ['no message'])[-1]}"
    scoring, labels = r.stdout.strip().splitlines()[-2:]
    return {
        k: dict(zip(FUNCS, (float(v) for v in line.split()))) for k, line in (("scoring", scoring), ("labels", labels))
    }


def calls_per_pair(cc: str, tmp: Path, rows: int, seed: int) -> None:
    counts = count_calls(cc, tmp, rows, seed)
    if isinstance(counts, str):
        print(f"calls per pair: skipped ({counts})")
        return
    print(f"C library calls per pair, one chunk of {rows:,} pairs:")
    for what, label in (
        ("labels", "both sides' matrices from their angles"),
        ("scoring", "every protocol but opal23-align"),
    ):
        print(f"  {label}: " + "  ".join(f"{f} {c:.2f}" for f, c in counts[what].items() if c >= 0.005))


def scalar_against_vector(cc: str, tmp: Path) -> None:
    exe = tmp / "loops"
    err = _compile(cc, LOOPS, exe, "-mavx2", "-mfma", "-lmvec")
    if err:
        print(f"scalar against vector: skipped (no AVX2 libmvec here: {err})")
        return
    r = subprocess.run([str(exe)], capture_output=True, text=True)
    if r.returncode:
        print("scalar against vector: skipped (the loops did not run on this CPU)")
        return
    print("glibc's scalar functions (numpy's, SciPy's) against its AVX2 vector ones, 4M random arguments:")
    print(f"  {'function':10s} {'scalar':>9s} {'vector':>9s}  {'results differing':>18s}  {'largest':>8s}")
    for line in r.stdout.split("\n"):
        if line.strip():
            name, ts, tv, pct, ulp = line.split()
            print(f"  {name:10s} {float(ts):6.1f} ns {float(tv):6.1f} ns  {float(pct):17.1f}%  {float(ulp):4.0f} ulp")


def scalar_costs(cc: str, tmp: Path):
    """``{function: ns a call}`` of glibc's scalar functions on this machine, or the reason (a string)."""
    exe = tmp / "costs"
    err = _compile(cc, COSTS, exe)
    if err:
        return f"the cost loops did not build: {err}"
    r = subprocess.run([str(exe)], capture_output=True, text=True)
    if r.returncode:
        return "the cost loops did not run"
    return {ln.split()[0]: float(ln.split()[1]) for ln in r.stdout.splitlines() if ln.strip()}


def rounding(samples: int) -> None:
    import numpy as np

    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_features__ as features
    svml = features.get("AVX512_SKX", False)
    r = subprocess.run([sys.executable, "-c", ROUNDING_CHILD, str(samples)], capture_output=True, text=True)
    if r.returncode:
        print(f"rounding: skipped ({(r.stderr.strip().splitlines() or ['no message'])[-1]})")
        return
    where = "Intel's SVML (this CPU has AVX512_SKX)" if svml else "glibc's (this CPU has no AVX512_SKX)"
    print(f"numpy {np.__version__}'s functions here are {where}; against mpmath, {samples:,} random arguments:")
    print(f"  {'function':10s} {'not correctly rounded':>22s}  {'largest error':>14s}")
    for line in r.stdout.splitlines():
        name, pct, worst = line.split()
        print(f"  {name:10s} {float(pct):21.3f}%  {float(worst):10.3f} ulp")


def vector_atan2(cc: str, tmp: Path) -> None:
    """A nearly correctly rounded AVX2 ``atan2`` against glibc's: its time, the share of results that are not glibc's
    bits, and the same behind a rounding test that keeps glibc's bits (falling back to glibc near a boundary)."""
    try:
        import mpmath
    except ImportError:
        print("correctly rounded vector atan2: skipped (no mpmath for its table)")
        return
    mpmath.mp.prec = 200
    hi, lo = [], []
    for j in range(65):
        v = mpmath.atan(mpmath.mpf(j) / 64)
        hi.append(float(v))
        lo.append(float(v - mpmath.mpf(hi[-1])))
    src = VECTOR_ATAN2.replace("{TABLE_HI}", "{" + ", ".join(h.hex() for h in hi) + "}")
    src = src.replace("{TABLE_LO}", "{" + ", ".join(v.hex() for v in lo) + "}")
    exe = tmp / "vatan2"
    err = _compile(cc, src, exe, "-mavx2", "-mfma", "-ffp-contract=off")
    r = None if err else subprocess.run([str(exe)], capture_output=True, text=True)
    if err or r.returncode:
        print(f"correctly rounded vector atan2: skipped ({err or 'it did not run on this CPU'})")
        return
    print("a nearly correctly rounded AVX2 atan2 (double-double, 65-entry table) against glibc's, 4M random arguments:")
    for line in r.stdout.splitlines():
        margin, tg, tv, diff, fb = (float(v) for v in line.split())
        how = (
            f"behind a rounding test ({margin:g} ulp margin, glibc as the fallback for {fb:.1f}% of values)"
            if margin
            else "alone"
        )
        print(f"  {how}: {tv:.1f} ns (glibc {tg:.1f} ns); results not glibc's bits: {diff:.3f}%")


def _timed(cmd: list, env: dict) -> float | None:
    import time

    t = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    return None if r.returncode else time.perf_counter() - t


def drop_in(cc: str, tmp: Path, pred: str, gt: str, rounds: int = 3) -> None:
    """The default run's time with glibc's atan2 and hypot and with the faster drop-ins, alternately."""
    import statistics

    lib = tmp / "libdropin.so"
    err = _compile(cc, DROP_IN, lib, "-shared", "-fPIC", "-ldl")
    if err:
        print(f"drop-in: skipped (it did not build: {err})")
        return
    hpe = shutil.which("hpe") or "hpe"
    cmd = [hpe, "evaluate", pred, gt, "--pred-system", "6drepnet", "--gt-system", "300w_lp"]
    cmd += ["--json", str(tmp / "dropin.json"), "-q", "--overwrite"]
    times: dict = {"glibc": [], "drop-in": []}
    for _ in range(rounds):
        for k, pre in (("glibc", None), ("drop-in", str(lib))):
            env = dict(os.environ, **({"LD_PRELOAD": pre} if pre else {}))
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            t = _timed(cmd, env)
            if t is None:
                print(f"drop-in: skipped (hpe evaluate failed with {k})")
                return
            times[k].append(t)
    g, d = statistics.median(times["glibc"]), statistics.median(times["drop-in"])
    print(
        f"the default run, median of {rounds}: glibc's atan2 and hypot {g:.2f} s; the drop-ins {d:.2f} s "
        f"({100 * (g - d) / g:.0f}% less)"
    )


def count_run(cc: str, tmp: Path, pred: str, gt: str, protocols=()) -> dict | str:
    """One ``hpe evaluate PRED GT`` (every protocol, or ``protocols``) under the counting shim: ``{"pairs",
    "calls": {function: calls}, "cpu", "wall"}``, or the reason it could not be counted (a string)."""
    import json
    import resource
    import time

    shim, err = _shim(cc, tmp)
    if err:
        return f"the counting shim did not build: {err}"
    out, counts = tmp / "report.json", tmp / "counts.txt"
    counts.unlink(missing_ok=True)
    env = dict(os.environ, LD_PRELOAD=str(shim))
    args = ["evaluate", pred, gt, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "--json", str(out), "-q"]
    args += ["--overwrite", *(a for p in protocols for a in ("--protocol", p))]
    cmd = [sys.executable, "-c", RUN_CHILD, str(shim), str(counts), *args]
    before, t = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall, after = time.perf_counter() - t, resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode or not counts.exists():
        return f"hpe evaluate failed: {(r.stderr.strip().splitlines() or ['no message'])[-1]}"
    return {
        "pairs": json.loads(out.read_text())["n"]["pairs"],
        "calls": dict(zip(FUNCS, (int(v) for v in counts.read_text().split()))),
        "cpu": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
        "wall": wall,
    }


def cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def libm_seconds(calls: dict, costs: dict) -> float:
    """CPU seconds of ``calls`` at the scalar ``costs`` (ns a call)."""
    return sum(calls[f] * costs[f] for f in FUNCS) * 1e-9


def sites(cc: str, tmp: Path, pred: str, gt: str) -> None:
    """A default ``hpe evaluate`` run with each C library call counted by the function that made it: a kernel of
    ``_hpe_kernels`` by name, numpy's loops as numpy."""
    import json

    lib, out, table = tmp / "libsites.so", tmp / "report.json", tmp / "sites.txt"
    err = _compile(cc, SITES_SHIM, lib, "-shared", "-fPIC", "-ldl", "-lpthread")
    addr2line = shutil.which("addr2line")
    if err or addr2line is None:
        print(f"call sites: skipped ({err or 'no addr2line'})")
        return
    args = ["evaluate", pred, gt, "--pred-system", "6drepnet", "--gt-system", "300w_lp", "--json", str(out), "-q"]
    r = subprocess.run(
        [sys.executable, "-c", SITES_CHILD, str(lib), str(table), *args, "--overwrite"],
        env=dict(os.environ, LD_PRELOAD=str(lib)),
        capture_output=True,
        text=True,
    )
    if r.returncode or not table.exists():
        print(f"call sites: skipped (hpe evaluate failed: {(r.stderr.strip().splitlines() or ['no message'])[-1]})")
        return
    pairs = json.loads(out.read_text())["n"]["pairs"]
    by: dict = {}
    for line in table.read_text().splitlines():
        path, offset, *counts = line.split()
        if "_hpe_kernels" in path:
            name = subprocess.run([addr2line, "-f", "-e", path, offset], capture_output=True, text=True).stdout
            where = f"kernel {name.split()[0] if name.strip() else offset}"
        else:
            where = "numpy" if "_multiarray_umath" in path else Path(path).name
        by[where] = [a + int(b) for a, b in zip(by.get(where, [0] * 5), counts)]
    print(f"C library calls per pair by the function that made them, {pairs:,} pairs, every protocol:")
    print(f"  {'caller':34s}" + "".join(f"{f:>8s}" for f in SITE_FUNCS))
    for where, counts in sorted(by.items(), key=lambda kv: -sum(kv[1])):
        if sum(counts) >= 0.005 * pairs:
            print(f"  {where:34s}" + "".join(f"{c / pairs:8.2f}" for c in counts))


def whole_run(cc: str, tmp: Path, pred: str, gt: str) -> None:
    """A default ``hpe evaluate`` run under the shim: its calls per pair times their scalar costs."""
    costs = scalar_costs(cc, tmp)
    run = count_run(cc, tmp, pred, gt) if not isinstance(costs, str) else costs
    if isinstance(run, str):
        print(f"whole run: skipped ({run})")
        return
    pairs, calls, cpu, wall = run["pairs"], run["calls"], run["cpu"], run["wall"]
    floor = libm_seconds(calls, costs)
    print(f"hpe evaluate {pred} {gt}, every protocol, {pairs:,} pairs, under the counting shim:")
    print("  calls per pair: " + "  ".join(f"{f} {calls[f] / pairs:.2f}" for f in FUNCS if calls[f] >= 0.005 * pairs))
    print("  scalar cost per call here: " + "  ".join(f"{f} {costs[f]:.1f} ns" for f in FUNCS))
    print(
        f"  the C library's floor: {floor:.2f} s of CPU, {floor / cores():.2f} s of wall time on {cores()} cores; "
        f"the run: {cpu:.2f} s of CPU in {wall:.2f} s ({100 * floor / cpu:.0f}% of its CPU in these calls)"
    )


def compiler() -> str | None:
    """The C compiler the shims and loops are built with: ``$CC`` (default ``cc``), else ``gcc``, else None."""
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=65536, help="pairs in the counted chunk (default 65536)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--run", nargs=2, metavar=("PRED", "GT"), help="also a whole default hpe evaluate run")
    ap.add_argument("--drop-in", action="store_true", help="with --run: also time it with faster atan2 and hypot")
    ap.add_argument("--sites", action="store_true", help="with --run: also its calls by the function that made them")
    ap.add_argument("--samples", type=int, default=20000, help="random arguments of the rounding table")
    a = ap.parse_args(argv)
    cc = compiler()
    if cc is None:
        sys.exit("benchmarks/libm.py: no C compiler (set CC)")
    with tempfile.TemporaryDirectory(prefix="hpe_libm_") as tmp:
        calls_per_pair(cc, Path(tmp), a.rows, a.seed)
        scalar_against_vector(cc, Path(tmp))
        rounding(a.samples)
        vector_atan2(cc, Path(tmp))
        if a.run:
            whole_run(cc, Path(tmp), *a.run)
            if a.sites:
                sites(cc, Path(tmp), *a.run)
            if a.drop_in:
                drop_in(cc, Path(tmp), *a.run)


if __name__ == "__main__":
    main()
