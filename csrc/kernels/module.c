/* The _hpe_kernels module: its method table (each kernel in the file of its concept, kernels.h). */
#include "kernels.h"

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
    {"best_of_two", k_best_of_two, METH_VARARGS,
     "best_of_two(p1, p2, g, best, second, wrapped): the core angle errors (twins: "
     "hpe_cli.metrics.rotation_errors.best_of_two_error, wrapped_error)."},
    {"second_solution", k_second_solution, METH_VARARGS,
     "second_solution(p1, middle, proper, p2): the other Euler solution in degrees (twin: "
     "hpe_cli.rotation.solutions.second_degrees)."},
    {"libm", k_libm, METH_VARARGS, "libm(name, x, y, out): the C library's atan2, hypot, acos, asin, sin (probes)."},
    {"repeated_values", k_repeated_values, METH_VARARGS,
     "repeated_values(h) -> k: the repeated values of h, once each and sorted, to h[:k] (h is scratch; twin: "
     "hpe_cli.pipelines.audit.duplicates.repeated_in_place)."},
    {"bucket_file", k_bucket_file, METH_VARARGS,
     "bucket_file(h, arr, cursors, cap) -> bool: a batch's hashes to their buckets (False: a bucket is full)."},
    {"bucket_repeats", k_bucket_repeats, METH_VARARGS,
     "bucket_repeats(arr, cursors, cap, lo, hi) -> bytes: the repeated values of buckets lo .. hi - 1, sorted "
     "(twin: hpe_cli.pipelines.audit.duplicates.repeated_in_place)."},
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
                                    "hpe's optional compiled column kernels (csrc/kernels/).", -1, methods};

PyMODINIT_FUNC PyInit__hpe_kernels(void) { return PyModule_Create(&module); }
