/* Argument checks shared by the kernels (kernels.h). */
#include "kernels.h"

int need(Py_buffer *b, Py_ssize_t items, Py_ssize_t itemsize, const char *name) {
    if (b->len != items * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd bytes, got %zd", name, items * itemsize, b->len);
        return 0;
    }
    return 1;
}

int columns(PyObject *seq, Py_buffer *b, const double **p, int count, Py_ssize_t n, const char *name) {
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
    if (k == count && !PyErr_Occurred()) {
        if (p)
            for (int j = 0; j < count; j++) p[j] = (const double *)b[j].buf;
        return 1;
    }
    for (int j = 0; j < k; j++) PyBuffer_Release(&b[j]);
    return 0;
}

int nine(PyObject *seq, Py_buffer *b, const double **p, Py_ssize_t n, const char *name) {
    return columns(seq, b, p, 9, n, name);
}

int optional_buffer(PyObject *o, Py_buffer *b, int flags, int *have) {
    *have = 0;
    if (o == Py_None) return 1;
    if (PyObject_GetBuffer(o, b, flags) < 0) return 0;
    *have = 1;
    return 1;
}

void release(Py_buffer *b, int count) {
    for (int k = 0; k < count; k++) PyBuffer_Release(&b[k]);
}
