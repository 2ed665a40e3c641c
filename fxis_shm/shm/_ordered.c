/* Ordered memory accesses for the ring's seqlock (fxis_shm/shm/ordering.py).
 *
 * Python has no memory fences, and the seqlock needs them on weakly ordered CPUs
 * (ARM64): the writer's data stores must not become visible before the odd seq that
 * announces them, and a reader's data loads must not be satisfied after its final
 * seq check. These are the C11 fences and acquire/release accesses of the classic
 * seqlock, on 8-byte words of a buffer (the ring's mmap).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdatomic.h>
#include <stdint.h>

static int word_at(PyObject *buffer, Py_ssize_t offset, int writable, Py_buffer *view, uint64_t **word) {
    if (PyObject_GetBuffer(buffer, view, writable ? PyBUF_WRITABLE : PyBUF_SIMPLE) < 0)
        return -1;
    if (offset < 0 || offset % 8 != 0 || offset + 8 > view->len) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_ValueError, "no aligned 8-byte word at offset %zd of a %zd-byte buffer",
                     offset, view->len);
        return -1;
    }
    *word = (uint64_t *)((char *)view->buf + offset);
    if (((uintptr_t)*word) % 8 != 0) {
        PyBuffer_Release(view);
        PyErr_SetString(PyExc_ValueError, "the buffer is not 8-byte aligned");
        return -1;
    }
    return 0;
}

static PyObject *load_acquire(PyObject *self, PyObject *args) {
    PyObject *buffer;
    Py_ssize_t offset;
    Py_buffer view;
    uint64_t *word;
    if (!PyArg_ParseTuple(args, "On", &buffer, &offset) || word_at(buffer, offset, 0, &view, &word) < 0)
        return NULL;
    uint64_t value = __atomic_load_n(word, __ATOMIC_ACQUIRE);
    PyBuffer_Release(&view);
    return PyLong_FromUnsignedLongLong(value);
}

static PyObject *store_release(PyObject *self, PyObject *args) {
    PyObject *buffer;
    Py_ssize_t offset;
    unsigned long long value;
    Py_buffer view;
    uint64_t *word;
    if (!PyArg_ParseTuple(args, "OnK", &buffer, &offset, &value) || word_at(buffer, offset, 1, &view, &word) < 0)
        return NULL;
    __atomic_store_n(word, (uint64_t)value, __ATOMIC_RELEASE);
    PyBuffer_Release(&view);
    Py_RETURN_NONE;
}

static PyObject *fence_acquire(PyObject *self, PyObject *unused) {
    atomic_thread_fence(memory_order_acquire);
    Py_RETURN_NONE;
}

static PyObject *fence_release(PyObject *self, PyObject *unused) {
    atomic_thread_fence(memory_order_release);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"load_acquire", load_acquire, METH_VARARGS, "load_acquire(buffer, offset): the 8-byte word there, acquire-ordered."},
    {"store_release", store_release, METH_VARARGS, "store_release(buffer, offset, value): a release-ordered 8-byte store."},
    {"fence_acquire", fence_acquire, METH_NOARGS, "An acquire fence: earlier loads happen before later accesses."},
    {"fence_release", fence_release, METH_NOARGS, "A release fence: earlier accesses happen before later stores."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_ordered", "Ordered accesses for the ring's seqlock.", -1, methods};

PyMODINIT_FUNC PyInit__ordered(void) { return PyModule_Create(&module); }
