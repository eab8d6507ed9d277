/* The audit's repeated hashes: which 64-bit row hashes occur more than once, without sorting them (radix partitions
 * and hash sets in cache), and the buckets the checking threads file the hashes into as they stream. */
#include "kernels.h"

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

PyObject *k_repeated_values(PyObject *self, PyObject *args) {
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

PyObject *k_bucket_file(PyObject *self, PyObject *args) {
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

PyObject *k_bucket_repeats(PyObject *self, PyObject *args) {
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
