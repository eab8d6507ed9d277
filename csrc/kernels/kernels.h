/* hpe's optional compiled column kernels (the _hpe_kernels module): what the kernel files share.
 *
 * Each kernel is one loop over a column where numpy takes a dozen passes or more, or a data-dependent loop numpy
 * cannot express (a hash over each string's bytes); each has a numpy twin in hpe_cli (named in its comment) that
 * gives the same bits, and tests/native/ compares the two. The hashes and the screens compute integers, fabs,
 * differences and comparisons only. The rotation and error kernels add IEEE sums, products and square roots in the
 * order of their twins' numpy operations (the build passes -ffp-contract=off: no fused multiply-adds) and call the
 * C library's sincos, atan2, hypot, acos, asin and sin, which hpe_cli.native uses only where they give numpy's
 * bits on a probe of values (the two that repeat SciPy's Rotation, which calls the C library itself: where they
 * give SciPy's bits on a probe). The arguments are buffers (numpy arrays), checked for size; the GIL is released in
 * the loops, so the threads that call them run in parallel.
 *
 * Files, by concept: buffers.c (argument checks), hashes.c (key and row hashes), screen.c (the audit's angle
 * screen), rotations.c (sines and cosines, Euler splits, quaternions, the probes' C library calls), errors.c
 * (evaluate's error formulas), repeats.c (the audit's repeated hashes), join.c (evaluate's key join), module.c (the
 * method table).
 */
#ifndef HPE_KERNELS_H
#define HPE_KERNELS_H
#define _GNU_SOURCE /* sincos */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#if defined(__GNUC__)
#define HPE_INTERNAL __attribute__((visibility("hidden")))
#else
#define HPE_INTERNAL
#endif

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

/* c ? a : b without a branch (the data's signs are random: a branch would be mispredicted half the time) */
static inline double sel(int c, double a, double b) {
    uint64_t ua, ub, m = (uint64_t)0 - (uint64_t)(c != 0);
    memcpy(&ua, &a, 8);
    memcpy(&ub, &b, 8);
    ua = (ua & m) | (ub & ~m);
    memcpy(&a, &ua, 8);
    return a;
}

/* buffers.c: a buffer of `items` items of `itemsize` bytes, else ValueError "name: expected N bytes, got M" */
HPE_INTERNAL int need(Py_buffer *b, Py_ssize_t items, Py_ssize_t itemsize, const char *name);
/* `count` C-contiguous float64 columns of n rows from a sequence, their data pointers in p (unless NULL); released
 * on failure */
HPE_INTERNAL int columns(PyObject *seq, Py_buffer *b, const double **p, int count, Py_ssize_t n, const char *name);
HPE_INTERNAL int nine(PyObject *seq, Py_buffer *b, const double **p, Py_ssize_t n, const char *name);
/* an argument that is None or a buffer: 1 with *have = 0 or 1 (the buffer got with `flags`), 0 on an error */
HPE_INTERNAL int optional_buffer(PyObject *o, Py_buffer *b, int flags, int *have);
HPE_INTERNAL void release(Py_buffer *b, int count);

/* rotations.c: SciPy's from_matrix quaternion (Markley's method, normalised) of a row-major 3x3 matrix */
HPE_INTERNAL void quat_of_matrix(const double *r, double q[4]);

/* the kernels (module.c lists them) */
HPE_INTERNAL PyObject *k_string_hashes(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_row_hash_add(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_mix(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_angle_screen(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_sin_cos(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_core_errors(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_euler_from_matrix(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_quat_matrix_from_euler(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_wrapped_cos_errors(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_opal23_mae(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_trace_acos_deg(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_near_quats(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_quat_rotvecs(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_system_angles(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_libm(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_best_of_two(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_second_solution(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_split_top_bit(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_repeated_values(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_bucket_file(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_bucket_repeats(PyObject *self, PyObject *args);
/* join.c: evaluate's key join */
HPE_INTERNAL PyObject *k_hash_pairs(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_first_unequal(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_partition_scatter(PyObject *self, PyObject *args);
HPE_INTERNAL PyObject *k_partition_strings(PyObject *self, PyObject *args);

#endif
