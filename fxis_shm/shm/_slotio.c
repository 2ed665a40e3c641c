/* The ring reader's hot loops in C (fxis_shm/shm/slotio.py chooses this or its Python twin).
 *
 * Three seqlock reads over a ring's mapping, each the C11 reader of the classic seqlock
 * (docs/design.md, "Memory ordering"): acquire loads of `seq`, plain loads or a memcpy of
 * what it guards, an acquire fence, then `seq` again.
 *
 *   records(buffer, table, slots, lo, hi)  the slot records of writes lo..hi-1 that were
 *                                          whole while read: a list of (w, frame_id,
 *                                          t_capture, t_stored, t_available, generation,
 *                                          t_target, capture)
 *   copy(buffer, seq_at, seq, src, nbytes, out)  memcpy of a slot into `out` (the GIL let
 *                                          go) if `seq` held before and after: 0, else 1
 *                                          (overwritten before) or 2 (during)
 *   copies([(buffer, seq_at, seq, src, nbytes, out), ...])  copy of each, in order, the GIL
 *                                          let go once: None, or (index, 1 or 2) of the first
 *                                          frame not whole (the later ones are left)
 *   holds(buffer, seq_at, seq)             an acquire fence, then: does the slot still show seq?
 *
 * The layout (offsets, the 64-byte record) is the ring's (fxis_shm/shm/ring.py); every
 * offset is checked against the buffer's length. Errors raise ValueError.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdatomic.h>
#include <stdint.h>

#include "seqlock.h"


static int in_bounds(Py_buffer *view, Py_ssize_t offset, Py_ssize_t len) {
    if (offset < 0 || len < 0 || offset > view->len - len || ((uintptr_t)view->buf + offset) % 8 != 0) {
        PyErr_Format(PyExc_ValueError, "no aligned %zd bytes at offset %zd of a %zd-byte buffer", len, offset,
                     view->len);
        return 0;
    }
    return 1;
}

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
        Record r;
        if (read_record(rec, 2 * w + 2, &r))
            continue;
        PyObject *item = Py_BuildValue("(KKLLLKLK)", w, (unsigned long long)r.frame_id, (long long)r.t_capture,
                                       (long long)r.t_stored, (long long)r.t_available,
                                       (unsigned long long)r.generation, (long long)r.t_target,
                                       (unsigned long long)r.capture);
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

/* One frame: its buffers and offsets, checked against each other (holding the GIL). */
typedef struct {
    Py_buffer view, out;
    Py_ssize_t seq_at, src, nbytes;
    unsigned long long expected;
} Job;

static int job_open(Job *job, PyObject *buffer, PyObject *target) {
    if (PyObject_GetBuffer(buffer, &job->view, PyBUF_SIMPLE) < 0)
        return 0;
    if (PyObject_GetBuffer(target, &job->out, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0) {
        PyBuffer_Release(&job->view);
        return 0;
    }
    Py_buffer *view = &job->view;
    if (!in_bounds(view, job->seq_at, 8))
        goto fail;
    if (job->src < 0 || job->nbytes < 0 || job->src > view->len - job->nbytes) {
        PyErr_Format(PyExc_ValueError, "copy: no %zd bytes at offset %zd of a %zd-byte buffer", job->nbytes, job->src,
                     view->len);
        goto fail;
    }
    if (job->out.len != job->nbytes) {
        PyErr_Format(PyExc_ValueError, "copy: the target holds %zd bytes, the frame %zd", job->out.len, job->nbytes);
        goto fail;
    }
    return 1;
fail:
    PyBuffer_Release(&job->out);
    PyBuffer_Release(&job->view);
    return 0;
}

static void job_close(Job *job) {
    PyBuffer_Release(&job->out);
    PyBuffer_Release(&job->view);
}

/* The seqlock read of one frame (without the GIL): 0 whole, 1/2 overwritten before/during. */
static int job_run(Job *job, int stream) {
    const char *base = (const char *)job->view.buf;
    return copy_whole(base + job->seq_at, job->expected, job->out.buf, base + job->src, (size_t)job->nbytes, stream);
}

static PyObject *copy(PyObject *self, PyObject *args) {
    PyObject *buffer, *target;
    Job job;
    if (!PyArg_ParseTuple(args, "OnKnnO", &buffer, &job.seq_at, &job.expected, &job.src, &job.nbytes, &target))
        return NULL;
    if (!job_open(&job, buffer, target))
        return NULL;
    int result;
    Py_BEGIN_ALLOW_THREADS
    result = job_run(&job, 0);
    Py_END_ALLOW_THREADS
    job_close(&job);
    return PyLong_FromLong(result);
}

#define MAX_JOBS 64

static PyObject *copies(PyObject *self, PyObject *args) {
    PyObject *items;
    if (!PyArg_ParseTuple(args, "O!", &PyList_Type, &items))
        return NULL;
    Py_ssize_t n = PyList_GET_SIZE(items), opened = 0, k;
    if (n > MAX_JOBS) {
        PyErr_Format(PyExc_ValueError, "copies: at most %d frames at once, got %zd", MAX_JOBS, n);
        return NULL;
    }
    Job jobs[MAX_JOBS];
    for (; opened < n; opened++) {
        Job *job = &jobs[opened];
        PyObject *buffer, *target;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(items, opened), "OnKnnO;copies: (buffer, seq_at, seq, src, nbytes, out)",
                              &buffer, &job->seq_at, &job->expected, &job->src, &job->nbytes, &target) ||
            !job_open(job, buffer, target))
            break;
    }
    int result = 0;
    if (opened == n) {
        Py_BEGIN_ALLOW_THREADS
        for (k = 0; k < n && (result = job_run(&jobs[k], 1)) == 0; k++)
            ;
        Py_END_ALLOW_THREADS
    }
    for (Py_ssize_t j = 0; j < opened; j++)
        job_close(&jobs[j]);
    if (opened < n)
        return NULL;
    if (result == 0)
        Py_RETURN_NONE;
    return Py_BuildValue("(ni)", k, result);
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
    {"copies", copies, METH_VARARGS,
     "copies([(buffer, seq_at, seq, src, nbytes, out), ...]): each as copy(), in order, the GIL let go once; "
     "None if all were whole, else (index, 1 or 2) of the first that was not (the later ones are not copied)."},
    {"holds", holds, METH_VARARGS, "holds(buffer, seq_at, seq): after an acquire fence, does the slot show seq?"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_slotio", "The ring reader's seqlock reads in C.", -1, methods};

PyMODINIT_FUNC PyInit__slotio(void) { return PyModule_Create(&module); }
