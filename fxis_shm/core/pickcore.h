/* The decision of a request for one frame per camera near t*, in C: the twin of `_near` in
 * fxis_shm/core/decisions.py (with the searches of timesearch.py, the selections of
 * selection.py and the `auto` wait of waitpolicy.py) for the requests the compiled fast path
 * takes: image and tuple with `at` given, wait "auto" or "none", sync "joint" or
 * "independent", no software trigger. tests/unit/test_pickcore.py checks with hypothesis
 * (random timelines, clocks and requests) that both decide the same.
 *
 * Pure: timelines (read through each camera's `read`) and numbers in, a decision out. What
 * the Python answers with an error, or by waiting, this answers with PICK_REJECT or
 * PICK_WAIT, and the caller lets the Python engine do it (and say why). A tuple whose
 * lockstep frames come from different grid points (selection.on_grid: the Python then looks
 * for a tuple of one point, or flags the reply) is PICK_UNSUPPORTED: rare, and the Python's. */
#ifndef FXIS_PICKCORE_H
#define FXIS_PICKCORE_H

#include <stdint.h>

#define PICK_MAX_CAMS 32
#define PICK_MAX_PREDICTED 64   /* predicted frames per camera (more: PICK_UNSUPPORTED) */
#define PICK_MAX_EVENTS 1024    /* candidate frames of a joint selection (more: PICK_UNSUPPORTED) */

enum {
    /* PLAN, WAIT and REJECT move a waiting request as the engine's decisions do (its states,
     * fxis_shm/core/requeststate.py): to ANSWERED, not at all, to FAILED; the differential
     * tests check the engine's request is in that state (tests/virtualtime/cell.py) */
    PICK_PLAN = 0,        /* the frames are chosen: each camera's `index` and `t` */
    PICK_WAIT = 1,        /* the request must wait: each camera's `waits` */
    PICK_REJECT = 2,      /* the request fails: PickResult.reject names the error code */
    PICK_UNSUPPORTED = 3, /* beyond this twin's limits (the Python engine decides) */
    PICK_UNREAD = 4,      /* a `read` found its record overwritten (look again, or let Python) */
};

typedef struct PickCam PickCam;
struct PickCam {
    /* in */
    int64_t (*read)(PickCam *cam, int64_t i); /* t_capture of stored logical index i, oldest first */
    int64_t (*grid)(PickCam *cam, int64_t i); /* its t_target if captured on the lockstep grid, else 0;
                                                 NULL: no lockstep frames */
    void *source;                             /* what `read` reads */
    int64_t base;                             /* for `read`: e.g. the write index of logical index 0 */
    int64_t stored;                           /* how many frames are stored */
    int rank;         /* the camera's place by name among the request's (Python breaks time ties by name) */
    int64_t period_ns; /* the measured frame period; 0: not known yet */
    int64_t delay_ns;  /* capture to storage, >= 0 */
    /* the core's */
    int failed; /* `read` found a record that was not whole */
    int64_t predicted[PICK_MAX_PREDICTED];
    int64_t n_predicted;
    /* out */
    int64_t index, t; /* PICK_PLAN: the chosen logical index and its capture time */
    int waits;        /* PICK_WAIT: the request waits for this camera */
};

typedef struct {
    int64_t t_star, now;
    int tuple;                    /* op tuple (else image: independent, no skew limit) */
    int joint;                    /* sync joint (else independent) */
    int wait_auto;                /* wait auto (else none) */
    int check_history;            /* `at` was given: a t* over half a period older than a ring is an error */
    int64_t tolerance_setting_ns; /* int(sync_tolerance_ms * 1e6) */
    double max_skew_ns;           /* max_skew_ms * 1e6; < 0: no limit */
} PickRequest;

typedef struct {
    int64_t skew_ns;    /* PICK_PLAN: the tuple's skew */
    const char *reject; /* PICK_REJECT: the error code (NO_FRAMES, OUT_OF_RANGE, SKEW_EXCEEDED) */
} PickResult;

int pick_near(PickCam *cams, int n, const PickRequest *request, PickResult *result);

#endif
