/* The compiled same-host read: one call that looks at the rings, decides, and copies.
 *
 *   Rings(rings, layout, fresh)  the rings of one service as this process maps them. `rings`: per
 *       camera (buffer, slots, table_at, data_at, stride, nbytes, pooled); `layout`: (state_at, pid_at,
 *       write_count_at, heartbeat_at, period_at, delay_at, retired_state, stale_heartbeat_ns,
 *       alive_check_ns, clock_id), the ring header's offsets and the liveness rules of
 *       fxis_shm/shm/ring.py and cameras.py. `fresh(k)` makes a writable array for a frame of
 *       camera k (mapped in already): up to `pooled` of them are kept and handed out again
 *       once nothing but the pool refers to one (its reference count is 1), so a copy lands in
 *       memory that is mapped, and never in an array anyone can still read.
 *   Rings.pick(cams, ranks, op, t_star, joint, wait_auto, tolerance_ns, horizon_ns, copy, now=0)
 *       op 0 image, 1 tuple (frames near t_star, `at` given, no skew limit: fxis_shm/core/pickcore.c
 *       decides; a t_star more than horizon_ns ahead is the engine's error) or
 *       2 latest (each camera's newest frame). With `copy` the chosen slots are copied into
 *       arrays of the pool under the seqlock, the GIL let go. Returns (t_received, t_decided,
 *       t_copied, skew_ns, frames), each frame (slot, seq, frame_id, t_capture, t_stored,
 *       t_available, generation, t_target, capture, ready_at, array or None), or an int: why the Python
 *       engine must answer instead (FALLBACK_*, a camera down, a wait, an error to word).
 *       `now`: when the request arrived, in the service's clock (0: read the clock).
 *   decide_near(cams, t_star, now, tuple, joint, wait_auto, check_history, tolerance_ns,   (plainpick.c)
 *       max_skew_ns)  pickcore over plain timelines, for the differential tests: cams are
 *       (times, rank, period_ns, delay_ns[, grid points: each frame's t_target if lockstep, else 0]); returns (PLAN, indices, skew_ns), (WAIT, waited
 *       camera positions), (REJECT, code) or (UNSUPPORTED, None).
 *
 * Liveness follows CameraHandle.down_reason: a retired ring, a worker not running (a look at
 * /proc/PID/stat at most every alive_check_ns, or a new frame since the last look), or a
 * heartbeat older than stale_heartbeat_ns sends the request to the Python engine, which
 * reopens the ring or says the camera is down. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <fcntl.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <time.h>
#include <unistd.h>

#include "../core/pickcore.h"
#include "plainpick.h"
#include "seqlock.h"


enum { FALLBACK_RETIRED = 5, FALLBACK_DOWN = 6, FALLBACK_TORN = 7 };
enum { CAPTURE_LOCKSTEP = 2 }; /* a slot record's `capture` (fxis_shm.core.snapshot.CAPTURES) */
enum { OP_IMAGE = 0, OP_TUPLE = 1, OP_LATEST = 2 };

typedef struct {
    Py_buffer view;
    Py_ssize_t slots, table_at, data_at, stride, nbytes;
    PyObject **pool; /* arrays made by `fresh`, handed out again when only the pool holds them */
    Py_ssize_t pooled, pool_max;
    int64_t seen_pid, seen_at; /* the last look that found the worker running, and when */
    uint64_t seen_count;       /* the write count then */
} Ring;

typedef struct {
    PyObject_HEAD
    int n;
    Ring *rings;
    PyObject *fresh;
    Py_ssize_t state_at, pid_at, count_at, heartbeat_at, period_at, delay_at;
    unsigned int retired_state;
    int64_t stale_heartbeat_ns, alive_check_ns;
    clockid_t clock;
} Rings;

static int64_t clock_ns(clockid_t clock) {
    struct timespec ts;
    clock_gettime(clock, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* ---- one ring ---- */

static const char *base_of(const Ring *r) { return (const char *)r->view.buf; }

static const char *record_of(const Ring *r, int64_t w) {
    return base_of(r) + r->table_at + (Py_ssize_t)((uint64_t)w % (uint64_t)r->slots) * RECORD;
}

/* The record of write w, if whole while read (0), else 1. */
static int record_of_write(const Ring *r, int64_t w, Record *out) {
    return read_record(record_of(r, w), 2 * (uint64_t)w + 2, out);
}

/* pickcore's read: t_capture of write base + i, if its record was whole while read. */
static int64_t ring_time(PickCam *cam, int64_t i) {
    Record rec;
    if (record_of_write((const Ring *)cam->source, cam->base + i, &rec)) {
        cam->failed = 1;
        return 0;
    }
    return rec.t_capture;
}

/* pickcore's grid: t_target of write base + i if captured on the lockstep grid, else 0. */
static int64_t ring_grid(PickCam *cam, int64_t i) {
    Record rec;
    if (record_of_write((const Ring *)cam->source, cam->base + i, &rec)) {
        cam->failed = 1;
        return 0;
    }
    return rec.capture == CAPTURE_LOCKSTEP ? rec.t_target : 0;
}

/* procstat.read(pid).running: the process exists and is not a zombie (or dead). */
static int process_running(int64_t pid) {
    char path[64], buf[512];
    if (pid <= 0)
        return 0;
    snprintf(path, sizeof path, "/proc/%lld/stat", (long long)pid);
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return 0;
    ssize_t got = read(fd, buf, sizeof buf - 1);
    close(fd);
    if (got <= 0)
        return 0;
    buf[got] = 0;
    const char *paren = strrchr(buf, ')'); /* the command may hold spaces and parentheses */
    if (paren == NULL || paren[1] != ' ')
        return 0;
    char state = paren[2];
    return state != 'Z' && state != 'X' && state != 'x';
}

/* CameraHandle._alive: a frame stored since the last look is as good a sign of life as /proc. */
static int worker_alive(Rings *self, Ring *r, int64_t pid, uint64_t count) {
    int64_t checked = clock_ns(CLOCK_MONOTONIC);
    if (pid == r->seen_pid && (checked - r->seen_at < self->alive_check_ns || count != r->seen_count)) {
        if (count != r->seen_count)
            r->seen_at = checked;
        r->seen_count = count;
        return 1;
    }
    int alive = process_running(pid);
    r->seen_pid = alive ? pid : 0;
    r->seen_at = alive ? checked : 0;
    r->seen_count = alive ? count : 0;
    return alive;
}

/* The camera as pickcore reads it, or why the engine must look instead. */
static int look(Rings *self, Ring *r, int64_t now, PickCam *cam) {
    const char *h = base_of(r);
    if (*(const volatile uint32_t *)(h + self->state_at) == self->retired_state)
        return FALLBACK_RETIRED;
    int64_t pid = load_plain(h + self->pid_at), heartbeat = load_plain(h + self->heartbeat_at);
    uint64_t count = load_acquire(h + self->count_at);
    if (!worker_alive(self, r, pid, count) || now - heartbeat > self->stale_heartbeat_ns)
        return FALLBACK_DOWN;
    int64_t first = (int64_t)count > r->slots ? (int64_t)count - r->slots : 0;
    int64_t delay = load_plain(h + self->delay_at);
    cam->read = ring_time;
    cam->grid = ring_grid;
    cam->source = r;
    cam->base = first;
    cam->stored = (int64_t)count - first;
    cam->period_ns = load_plain(h + self->period_at);
    cam->delay_ns = delay > 0 ? delay : 0;
    return PICK_PLAN;
}

/* ---- Rings ---- */

static void rings_dealloc(Rings *self) {
    for (int k = 0; k < self->n; k++) {
        Ring *r = &self->rings[k];
        PyBuffer_Release(&r->view);
        for (Py_ssize_t j = 0; j < r->pooled; j++)
            Py_DECREF(r->pool[j]);
        PyMem_Free(r->pool);
    }
    PyMem_Free(self->rings);
    Py_XDECREF(self->fresh);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int rings_init(Rings *self, PyObject *args, PyObject *kwds) {
    PyObject *rings;
    unsigned int retired;
    int clock;
    if (self->rings != NULL) {
        PyErr_SetString(PyExc_TypeError, "Rings: already made");
        return -1;
    }
    if (!PyArg_ParseTuple(args, "O!(nnnnnnILLi)O", &PyList_Type, &rings, &self->state_at, &self->pid_at,
                          &self->count_at, &self->heartbeat_at, &self->period_at, &self->delay_at, &retired,
                          &self->stale_heartbeat_ns, &self->alive_check_ns, &clock, &self->fresh))
        return -1;
    if (!PyCallable_Check(self->fresh)) {
        self->fresh = NULL;
        PyErr_SetString(PyExc_TypeError, "Rings: fresh must be callable");
        return -1;
    }
    Py_INCREF(self->fresh);
    self->retired_state = retired;
    self->clock = (clockid_t)clock;
    Py_ssize_t n = PyList_GET_SIZE(rings);
    if (n < 1 || n > 4096) {
        PyErr_SetString(PyExc_ValueError, "Rings: need 1 to 4096 rings");
        return -1;
    }
    self->rings = PyMem_Calloc((size_t)n, sizeof(Ring));
    if (self->rings == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    for (; self->n < n; self->n++) {
        Ring *r = &self->rings[self->n];
        PyObject *buffer;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(rings, self->n), "Onnnnnn;Rings: (buffer, slots, table_at, data_at, "
                              "stride, nbytes, pooled)", &buffer, &r->slots, &r->table_at, &r->data_at, &r->stride,
                              &r->nbytes, &r->pool_max))
            return -1;
        if (r->pool_max < 0 || r->pool_max > 4096) {
            PyErr_SetString(PyExc_ValueError, "Rings: pool 0 to 4096 arrays per ring");
            return -1;
        }

        if (PyObject_GetBuffer(buffer, &r->view, PyBUF_SIMPLE) < 0)
            return -1;
        Py_ssize_t offsets[] = {self->state_at, self->pid_at, self->count_at, self->heartbeat_at, self->period_at,
                                self->delay_at};
        Py_ssize_t header_end = 0;
        for (int j = 0; j < 6; j++)
            header_end = offsets[j] < 0 || offsets[j] % 4   ? PY_SSIZE_T_MAX - 8
                         : offsets[j] > header_end ? offsets[j]
                                                   : header_end;
        if (r->slots < 1 || r->nbytes < 0 || r->stride < r->nbytes || header_end + 8 > r->table_at ||
            r->table_at > r->view.len - r->slots * RECORD || r->data_at < 0 ||
            r->data_at > r->view.len - r->nbytes - (r->slots - 1) * r->stride || (uintptr_t)r->view.buf % 8 ||
            r->table_at % 8) {
            PyBuffer_Release(&r->view);
            PyErr_Format(PyExc_ValueError, "Rings: ring %d does not fit its %zd-byte buffer", self->n, r->view.len);
            return -1;
        }
        if ((r->pool = PyMem_Calloc((size_t)r->pool_max + 1, sizeof(PyObject *))) == NULL) {
            PyBuffer_Release(&r->view);
            PyErr_NoMemory();
            return -1;
        }
    }
    return 0;
}

/* An array for a frame of ring `index`: a pooled one nothing else refers to, else a fresh one
 * (kept, if the pool has room). New reference; NULL with an exception. */
static PyObject *take_array(Rings *self, Py_ssize_t index) {
    Ring *r = &self->rings[index];
    for (Py_ssize_t j = 0; j < r->pooled; j++) {
        if (Py_REFCNT(r->pool[j]) == 1) {
            Py_INCREF(r->pool[j]);
            return r->pool[j];
        }
    }
    PyObject *fresh = PyObject_CallFunction(self->fresh, "n", index);
    if (fresh != NULL && r->pooled < r->pool_max) {
        Py_INCREF(fresh);
        r->pool[r->pooled++] = fresh;
    }
    return fresh;
}

/* The chosen frames into `outs`, under the seqlock, the GIL let go: 0, or FALLBACK_TORN. */
static int copy_out(Ring **rings, const int64_t *writes, PyObject *outs, int n) {
    Py_buffer targets[PICK_MAX_CAMS];
    int opened = 0, status = 0;
    for (; opened < n; opened++) {
        PyObject *out = PyList_GET_ITEM(outs, opened);
        if (PyObject_GetBuffer(out, &targets[opened], PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0)
            break;
        if (targets[opened].len != rings[opened]->nbytes) {
            PyErr_Format(PyExc_ValueError, "pick: out %d holds %zd bytes, the frame %zd", opened, targets[opened].len,
                         rings[opened]->nbytes);
            PyBuffer_Release(&targets[opened]);
            break;
        }
    }
    if (opened == n) {
        Py_BEGIN_ALLOW_THREADS
        for (int k = 0; k < n && status == 0; k++) {
            const Ring *r = rings[k];
            Py_ssize_t slot = (Py_ssize_t)((uint64_t)writes[k] % (uint64_t)r->slots);
            const char *src = base_of(r) + r->data_at + slot * r->stride;
            /* cached stores: the caller reads the frame next (timed: as fast cold as streamed, faster warm) */
            if (copy_whole(record_of(r, writes[k]), 2 * (uint64_t)writes[k] + 2, targets[k].buf, src,
                           (size_t)r->nbytes, 0))
                status = FALLBACK_TORN;
        }
        Py_END_ALLOW_THREADS
    }
    for (int k = 0; k < opened; k++)
        PyBuffer_Release(&targets[k]);
    return opened == n ? status : -1;
}

static PyObject *rings_pick(Rings *self, PyObject *args) {
    PyObject *cams_arg, *ranks_arg;
    int op, joint, wait_auto, copy;
    long long t_star, tolerance_ns, horizon_ns, now = 0;
    if (!PyArg_ParseTuple(args, "O!O!iLiiLLp|L", &PyTuple_Type, &cams_arg, &PyTuple_Type, &ranks_arg, &op, &t_star,
                          &joint, &wait_auto, &tolerance_ns, &horizon_ns, &copy, &now))
        return NULL;
    Py_ssize_t n = PyTuple_GET_SIZE(cams_arg);
    if (n < 1 || n > PICK_MAX_CAMS || PyTuple_GET_SIZE(ranks_arg) != n || op < OP_IMAGE || op > OP_LATEST) {
        PyErr_Format(PyExc_ValueError, "pick: 1 to %d cameras, as many ranks, op 0-2", PICK_MAX_CAMS);
        return NULL;
    }
    long indices[PICK_MAX_CAMS];
    PickCam cams[PICK_MAX_CAMS];
    Ring *rings[PICK_MAX_CAMS];
    int64_t t_received = now ? now : clock_ns(self->clock), newest_stored[PICK_MAX_CAMS], writes[PICK_MAX_CAMS];
    for (int k = 0; k < n; k++) {
        long index = indices[k] = PyLong_AsLong(PyTuple_GET_ITEM(cams_arg, k));
        if (index < 0 || index >= self->n) {
            if (!PyErr_Occurred())
                PyErr_Format(PyExc_IndexError, "pick: no ring %ld", index);
            return NULL;
        }
        rings[k] = &self->rings[index];
        cams[k].rank = (int)PyLong_AsLong(PyTuple_GET_ITEM(ranks_arg, k));
        if (cams[k].rank == -1 && PyErr_Occurred())
            return NULL;
        int status = look(self, rings[k], t_received, &cams[k]);
        if (status != PICK_PLAN)
            return PyLong_FromLong(status);
    }
    PickResult result = {0, NULL};
    int status;
    if (op == OP_LATEST) { /* decisions.newest_frames */
        status = PICK_PLAN;
        for (int k = 0; k < n; k++) {
            if (cams[k].stored == 0)
                return PyLong_FromLong(PICK_REJECT);
            cams[k].index = cams[k].stored - 1;
        }
    } else {
        if (t_star - t_received > horizon_ns) /* RequestEngine._admit: beyond the horizon */
            return PyLong_FromLong(PICK_REJECT);
        PickRequest request = {t_star, t_received, op == OP_TUPLE, joint, wait_auto, 1, tolerance_ns, -1.0};
        status = pick_near(cams, (int)n, &request, &result);
    }
    if (status != PICK_PLAN)
        return PyLong_FromLong(status);
    Record records[PICK_MAX_CAMS];
    for (int k = 0; k < n; k++) {
        Record newest;
        writes[k] = cams[k].base + cams[k].index;
        if (record_of_write(rings[k], writes[k], &records[k]) ||
            record_of_write(rings[k], cams[k].base + cams[k].stored - 1, &newest))
            return PyLong_FromLong(PICK_UNREAD);
        newest_stored[k] = newest.t_stored;
    }
    int64_t t_decided = clock_ns(self->clock);
    PyObject *outs = NULL;
    if (copy) {
        if ((outs = PyList_New(n)) == NULL)
            return NULL;
        for (int k = 0; k < n; k++) {
            PyObject *array = take_array(self, indices[k]);
            if (array == NULL) {
                Py_DECREF(outs);
                return NULL;
            }
            PyList_SET_ITEM(outs, k, array);
        }
        status = copy_out(rings, writes, outs, (int)n);
        if (status) {
            Py_DECREF(outs);
            return status < 0 ? NULL : PyLong_FromLong(status);
        }
    }
    int64_t t_copied = copy ? clock_ns(self->clock) : t_decided;
    PyObject *frames = PyTuple_New(n);
    if (frames == NULL) {
        Py_XDECREF(outs);
        return NULL;
    }
    for (int k = 0; k < n; k++) {
        const Record *rec = &records[k];
        int64_t ready = newest_stored[k] > t_received ? newest_stored[k] : t_received;
        PyObject *frame = Py_BuildValue("(nKKLLLKLKLO)", (Py_ssize_t)((uint64_t)writes[k] % (uint64_t)rings[k]->slots),
                                        (unsigned long long)(2 * (uint64_t)writes[k] + 2),
                                        (unsigned long long)rec->frame_id, (long long)rec->t_capture,
                                        (long long)rec->t_stored, (long long)rec->t_available,
                                        (unsigned long long)rec->generation, (long long)rec->t_target,
                                        (unsigned long long)rec->capture, (long long)ready,
                                        outs ? PyList_GET_ITEM(outs, k) : Py_None);
        if (frame == NULL) {
            Py_DECREF(frames);
            Py_XDECREF(outs);
            return NULL;
        }
        PyTuple_SET_ITEM(frames, k, frame);
    }
    Py_XDECREF(outs);
    return Py_BuildValue("(LLLLN)", (long long)t_received, (long long)t_decided, (long long)t_copied,
                         (long long)result.skew_ns, frames);
}

static PyMethodDef rings_methods[] = {
    {"pick", (PyCFunction)rings_pick, METH_VARARGS,
     "pick(cams, ranks, op, t_star, joint, wait_auto, tolerance_ns, horizon_ns, copy, now=0): the frames, or an int "
     "(why the Python engine must answer)."},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject RingsType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "fxis_shm.shm._fastpick.Rings",
    .tp_basicsize = sizeof(Rings),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "The rings of one service as this process maps them (see the module's help).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)rings_init,
    .tp_dealloc = (destructor)rings_dealloc,
    .tp_methods = rings_methods,
};

static PyMethodDef methods[] = {
    {"decide_near", decide_near, METH_VARARGS,
     "decide_near(cams, t_star, now, tuple, joint, wait_auto, check_history, tolerance_ns, max_skew_ns): "
     "pickcore's decision over plain timelines (cams: [(times, rank, period_ns, delay_ns[, grid]), ...])."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_fastpick", "The compiled same-host read.", -1, methods};

PyMODINIT_FUNC PyInit__fastpick(void) {
    if (PyType_Ready(&RingsType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&RingsType);
    if (PyModule_AddObject(m, "Rings", (PyObject *)&RingsType) < 0) {
        Py_DECREF(&RingsType);
        Py_DECREF(m);
        return NULL;
    }
    static const char *names[] = {"PLAN", "WAIT", "REJECT", "UNSUPPORTED", "UNREAD", "RETIRED", "DOWN", "TORN"};
    for (int k = 0; k < 8; k++)
        if (PyModule_AddIntConstant(m, names[k], k) < 0)
            return NULL;
    return m;
}
