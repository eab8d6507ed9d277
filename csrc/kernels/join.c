/* evaluate's key join (hpe_cli/pipelines/evaluate/spill.py): a chunk's rows put in partition order, a partition's
 * rows paired by their 64-bit key hashes, every pair verified on the key bytes. */
#include "kernels.h"

#include <stdlib.h>

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

PyObject *k_hash_pairs(PyObject *self, PyObject *args) {
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
PyObject *k_first_unequal(PyObject *self, PyObject *args) {
    Py_buffer oa, da, ob, db, rb, ra = {0};
    PyObject *ra_o;
    int wa, wb;
    if (!PyArg_ParseTuple(args, "y*y*Oy*y*y*pp", &oa, &da, &ra_o, &ob, &db, &rb, &wa, &wb)) return NULL;
    PyObject *ret = NULL;
    int have_ra = 0;
    Py_ssize_t m = rb.len / 8, j, bad = -1;
    Py_ssize_t na = oa.len / (wa ? 8 : 4) - 1, nb = ob.len / (wb ? 8 : 4) - 1;
    if (!optional_buffer(ra_o, &ra, PyBUF_SIMPLE, &have_ra)) goto done;
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

PyObject *k_partition_scatter(PyObject *self, PyObject *args) {
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
PyObject *k_partition_strings(PyObject *self, PyObject *args) {
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
