/* _fastpick.decide_near: pickcore over plain timelines (lists of capture times), for the
 * differential tests (tests/unit/test_pickcore.py) that show it decides as the Python does. */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "../core/pickcore.h"
#include "plainpick.h"

/* source: the capture times, then (with grid points) as many grid points */
static int64_t array_time(PickCam *cam, int64_t i) { return ((const int64_t *)cam->source)[i]; }

static int64_t array_grid(PickCam *cam, int64_t i) { return ((const int64_t *)cam->source)[cam->stored + i]; }

static int read_ints(PyObject *list, int64_t *into) {
    for (Py_ssize_t i = 0; i < PyList_GET_SIZE(list); i++) {
        into[i] = PyLong_AsLongLong(PyList_GET_ITEM(list, i));
        if (PyErr_Occurred())
            return -1;
    }
    return 0;
}

PyObject *decide_near(PyObject *module, PyObject *args) {
    PyObject *cams_arg;
    PickRequest r;
    if (!PyArg_ParseTuple(args, "O!LLiiiiLd", &PyList_Type, &cams_arg, &r.t_star, &r.now, &r.tuple, &r.joint,
                          &r.wait_auto, &r.check_history, &r.tolerance_setting_ns, &r.max_skew_ns))
        return NULL;
    Py_ssize_t n = PyList_GET_SIZE(cams_arg);
    if (n < 1 || n > PICK_MAX_CAMS) {
        PyErr_Format(PyExc_ValueError, "decide_near: 1 to %d cameras", PICK_MAX_CAMS);
        return NULL;
    }
    PickCam cams[PICK_MAX_CAMS];
    int64_t *times[PICK_MAX_CAMS] = {NULL};
    PyObject *out = NULL;
    int k;
    for (k = 0; k < n; k++) {
        PyObject *list, *grid = NULL;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(cams_arg, k),
                              "O!iLL|O!;decide_near: (times, rank, period_ns, delay_ns[, grid])", &PyList_Type, &list,
                              &cams[k].rank, &cams[k].period_ns, &cams[k].delay_ns, &PyList_Type, &grid))
            goto done;
        Py_ssize_t count = PyList_GET_SIZE(list);
        if (grid != NULL && PyList_GET_SIZE(grid) != count) {
            PyErr_SetString(PyExc_ValueError, "decide_near: a grid point per frame");
            goto done;
        }
        times[k] = PyMem_Malloc(sizeof(int64_t) * (size_t)(count ? 2 * count : 1));
        if (times[k] == NULL) {
            PyErr_NoMemory();
            goto done;
        }
        if (read_ints(list, times[k]) < 0 || (grid != NULL && read_ints(grid, times[k] + count) < 0))
            goto done;
        cams[k].read = array_time;
        cams[k].grid = grid == NULL ? NULL : array_grid;
        cams[k].source = times[k];
        cams[k].base = 0;
        cams[k].stored = count;
    }
    PickResult result;
    int status = pick_near(cams, (int)n, &r, &result);
    if (status == PICK_PLAN) {
        PyObject *indices = PyTuple_New(n);
        if (indices == NULL)
            goto done;
        for (int j = 0; j < n; j++)
            PyTuple_SET_ITEM(indices, j, PyLong_FromLongLong(cams[j].index));
        out = Py_BuildValue("(iNL)", status, indices, (long long)result.skew_ns);
    } else if (status == PICK_WAIT) {
        PyObject *waited = PyList_New(0);
        for (int j = 0; waited != NULL && j < n; j++) {
            PyObject *position = cams[j].waits ? PyLong_FromLong(j) : NULL;
            if (position != NULL && PyList_Append(waited, position) < 0)
                Py_CLEAR(waited);
            Py_XDECREF(position);
        }
        out = waited == NULL ? NULL : Py_BuildValue("(iN)", status, PyList_AsTuple(waited));
        Py_XDECREF(waited);
    } else if (status == PICK_REJECT) {
        out = Py_BuildValue("(is)", status, result.reject);
    } else {
        out = Py_BuildValue("(iO)", status, Py_None);
    }
done:
    for (int j = 0; j < n; j++)
        PyMem_Free(times[j]);
    return out;
}

