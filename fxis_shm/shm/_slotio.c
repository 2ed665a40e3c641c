/* The ring reader's hot loops in C (fxis_shm/shm/slotio.py chooses this or its Python twin).
 *
 * Three seqlock reads over a ring's mapping, each the C11 reader of the classic seqlock
 * (docs/design.md, "Memory ordering"): acquire loads of `seq`, plain loads or a memcpy of
 * what it guards, an acquire fence, then `seq` again.
 *
 *   records(buffer, table, slots, lo, hi)  the slot records of writes lo..hi-1 that were
 *                                          whole while read: a list of (w, frame_id,
 *                                          t_capture, t_stored, t_available, generation)
 *   copy(buffer, seq_at, seq, src, nbytes, out)  memcpy of a slot into `out` (the GIL let
 *                                          go) if `seq` held before and after: 0, else 1
 *                                          (overwritten before) or 2 (during)
 *   holds(buffer, seq_at, seq)             an acquire fence, then: does the slot still show seq?
 *
 * The layout (offsets, the 48-byte record) is the ring's (fxis_shm/shm/ring.py); every
 * offset is checked against the buffer's length. Errors raise ValueError.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdatomic.h>
#include <stdint.h>
#include <string.h>

#define RECORD 48 /* seq, frame_id, t_capture, t_stored, t_available, generation: 8 bytes each */

static int in_bounds(Py_buffer *view, Py_ssize_t offset, Py_ssize_t len) {
    if (offset < 0 || len < 0 || offset > view->len - len || ((uintptr_t)view->buf + offset) % 8 != 0) {
        PyErr_Format(PyExc_ValueError, "no aligned %zd bytes at offset %zd of a %zd-byte buffer", len, offset,
                     view->len);
        return 0;
    }
    return 1;
}

static inline uint64_t load_acquire(const char *at) { return __atomic_load_n((const uint64_t *)at, __ATOMIC_ACQUIRE); }

static inline int64_t load_plain(const char *at) { return __atomic_load_n((const int64_t *)at, __ATOMIC_RELAXED); }

static PyObject *records(PyObject *self, PyObject *args) {
    PyObject *buffer;
    Py_ssize_t table, slots;
    unsigned long long lo, hi;
    Py_buffer view;
    if (!PyArg_ParseTuple(args, "OnnKK", &buffer, &table, &slots, &lo, &hi))
        return NULL;
    if (slots <= 0 || hi < lo) {
        PyErr_SetString(PyExc_ValueError, "records: need slots > 0 and lo <= hi");
        return NULL;
    }
    if (PyObject_GetBuffer(buffer, &view, PyBUF_SIMPLE) < 0)
        return NULL;
    PyObject *out = NULL;
    if (!in_bounds(&view, table, slots * RECORD))
        goto done;
    out = PyList_New(0);
    if (out == NULL)
        goto done;
    for (unsigned long long w = lo; w < hi; w++) {
        const char *rec = (const char *)view.buf + table + (Py_ssize_t)(w % (unsigned long long)slots) * RECORD;
        uint64_t expected = 2 * w + 2;
        if (load_acquire(rec) != expected)
            continue;
        uint64_t frame_id = (uint64_t)load_plain(rec + 8);
        int64_t t_capture = load_plain(rec + 16), t_stored = load_plain(rec + 24);
        int64_t t_available = load_plain(rec + 32);
        uint64_t generation = (uint64_t)load_plain(rec + 40);
        atomic_thread_fence(memory_order_acquire); /* the fields were read before seq is read again */
        if (load_acquire(rec) != expected)
            continue;
        PyObject *item = Py_BuildValue("(KKLLLK)", w, frame_id, (long long)t_capture, (long long)t_stored,
                                       (long long)t_available, generation);
        if (item == NULL || PyList_Append(out, item) < 0) {
            Py_XDECREF(item);
            Py_CLEAR(out);
            goto done;
        }
        Py_DECREF(item);
    }
done:
    PyBuffer_Release(&view);
    return out;
}

static PyObject *copy(PyObject *self, PyObject *args) {
    PyObject *buffer, *target;
    Py_ssize_t seq_at, src, nbytes;
    unsigned long long expected;
    Py_buffer view, out;
    if (!PyArg_ParseTuple(args, "OnKnnO", &buffer, &seq_at, &expected, &src, &nbytes, &target))
        return NULL;
    if (PyObject_GetBuffer(buffer, &view, PyBUF_SIMPLE) < 0)
        return NULL;
    if (PyObject_GetBuffer(target, &out, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&view);
        return NULL;
    }
    long result = -1;
    if (!in_bounds(&view, seq_at, 8))
        goto done;
    if (src < 0 || nbytes < 0 || src > view.len - nbytes) {
        PyErr_Format(PyExc_ValueError, "copy: no %zd bytes at offset %zd of a %zd-byte buffer", nbytes, src, view.len);
        goto done;
    }
    if (out.len != nbytes) {
        PyErr_Format(PyExc_ValueError, "copy: the target holds %zd bytes, the frame %zd", out.len, nbytes);
        goto done;
    }
    const char *seq = (const char *)view.buf + seq_at;
    if (load_acquire(seq) != expected) {
        result = 1;
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    memcpy(out.buf, (const char *)view.buf + src, (size_t)nbytes);
    atomic_thread_fence(memory_order_acquire); /* every byte was read before seq is read again */
    Py_END_ALLOW_THREADS
    result = load_acquire(seq) == expected ? 0 : 2;
done:
    PyBuffer_Release(&out);
    PyBuffer_Release(&view);
    return result < 0 ? NULL : PyLong_FromLong(result);
}

static PyObject *holds(PyObject *self, PyObject *args) {
    PyObject *buffer;
    Py_ssize_t seq_at;
    unsigned long long expected;
    Py_buffer view;
    if (!PyArg_ParseTuple(args, "OnK", &buffer, &seq_at, &expected))
        return NULL;
    if (PyObject_GetBuffer(buffer, &view, PyBUF_SIMPLE) < 0)
        return NULL;
    if (!in_bounds(&view, seq_at, 8)) {
        PyBuffer_Release(&view);
        return NULL;
    }
    atomic_thread_fence(memory_order_acquire); /* what was read of the slot, before this check */
    int same = load_acquire((const char *)view.buf + seq_at) == expected;
    PyBuffer_Release(&view);
    return PyBool_FromLong(same);
}

static PyMethodDef methods[] = {
    {"records", records, METH_VARARGS, "records(buffer, table, slots, lo, hi): the whole records of writes lo..hi-1."},
    {"copy", copy, METH_VARARGS, "copy(buffer, seq_at, seq, src, nbytes, out): 0 copied whole, 1/2 overwritten before/during."},
    {"holds", holds, METH_VARARGS, "holds(buffer, seq_at, seq): after an acquire fence, does the slot show seq?"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_slotio", "The ring reader's seqlock reads in C.", -1, methods};

PyMODINIT_FUNC PyInit__slotio(void) { return PyModule_Create(&module); }
