/* _fastpick.decide_near (plainpick.c): pickcore over plain timelines, for the differential tests. */
#ifndef FXIS_PLAINPICK_H
#define FXIS_PLAINPICK_H

#include <Python.h>

PyObject *decide_near(PyObject *module, PyObject *args);

#endif
