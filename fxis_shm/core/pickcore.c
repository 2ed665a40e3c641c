/* The decision of a request for frames near t*, in C (pickcore.h says what and why). Each
 * function names the Python it follows, step for step: the same searches, ties and order. */
#include "pickcore.h"

#include <stdlib.h>
#include <string.h>

#define MAX_STEPS 4096 /* prediction steps per camera (more: PICK_UNSUPPORTED) */

typedef struct {
    int64_t index[PICK_MAX_CAMS], t[PICK_MAX_CAMS];
    int64_t least_skew; /* the least skew any candidate tuple had; -1: not a joint selection */
} Selection;

/* ---- timesearch.Timeline over stored frames, and with `extended` the predicted ones too ---- */

static int64_t length(const PickCam *c, int extended) { return c->stored + (extended ? c->n_predicted : 0); }

static int64_t at(PickCam *c, int64_t i) { return i >= c->stored ? c->predicted[i - c->stored] : c->read(c, i); }

static int64_t bisect_left(PickCam *c, int extended, int64_t t) {
    int64_t lo = 0, hi = length(c, extended);
    while (lo < hi) {
        int64_t mid = (lo + hi) / 2;
        if (at(c, mid) < t)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

static int64_t bisect_right(PickCam *c, int extended, int64_t t) {
    int64_t lo = 0, hi = length(c, extended);
    while (lo < hi) {
        int64_t mid = (lo + hi) / 2;
        if (at(c, mid) <= t)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* Timeline.nearest: the newest of equally near frames (the timeline is not empty). */
static int64_t nearest(PickCam *c, int extended, int64_t t_star) {
    int64_t count = length(c, extended);
    int64_t after = bisect_right(c, extended, t_star);
    if (after == count)
        return count - 1;
    int64_t t_after = at(c, after);
    int64_t newest_equal_after = bisect_right(c, extended, t_after) - 1;
    if (after == 0)
        return newest_equal_after;
    int64_t before = after - 1;
    if (t_star - at(c, before) < t_after - t_star)
        return before;
    return newest_equal_after;
}

/* ---- selection.py ---- */

static int64_t skew_of(const Selection *s, int n) {
    int64_t lo = s->t[0], hi = s->t[0];
    for (int k = 1; k < n; k++) {
        if (s->t[k] < lo)
            lo = s->t[k];
        if (s->t[k] > hi)
            hi = s->t[k];
    }
    return hi - lo;
}

static int64_t best_skew_of(const Selection *s, int n) { return s->least_skew < 0 ? skew_of(s, n) : s->least_skew; }

static int64_t distance(int64_t a, int64_t b) { return a > b ? a - b : b - a; }

static int64_t max_abs_error(const Selection *s, int n, int64_t t_star) {
    int64_t worst = 0;
    for (int k = 0; k < n; k++)
        if (distance(t_star, s->t[k]) > worst)
            worst = distance(t_star, s->t[k]);
    return worst;
}

static void select_independent(PickCam *cams, int n, int extended, int64_t t_star, Selection *s) {
    for (int k = 0; k < n; k++) {
        s->index[k] = nearest(&cams[k], extended, t_star);
        s->t[k] = at(&cams[k], s->index[k]);
    }
    s->least_skew = -1;
}

typedef struct {
    int64_t t, i;
    int rank, cam;
} Event;

static int by_time_name_index(const void *a, const void *b) {
    const Event *x = a, *y = b;
    if (x->t != y->t)
        return x->t < y->t ? -1 : 1;
    if (x->rank != y->rank)
        return x->rank < y->rank ? -1 : 1;
    return x->i < y->i ? -1 : x->i > y->i;
}

/* select_joint; PICK_UNSUPPORTED beyond PICK_MAX_EVENTS candidates, else PICK_PLAN. */
static int select_joint(PickCam *cams, int n, int extended, int64_t t_star, int64_t radius, int64_t tolerance,
                        Selection *s) {
    if (n == 1) {
        select_independent(cams, n, extended, t_star, s);
        return PICK_PLAN;
    }
    static __thread Event events[PICK_MAX_EVENTS];
    static __thread int starts[PICK_MAX_EVENTS], ends[PICK_MAX_EVENTS];
    int n_events = 0;
    int64_t centres[PICK_MAX_CAMS + 1]; /* _centres: t* and each camera's nearest frame */
    centres[0] = t_star;
    for (int k = 0; k < n; k++)
        centres[k + 1] = at(&cams[k], nearest(&cams[k], extended, t_star));
    for (int k = 0; k < n; k++) { /* _candidates: the frames within radius of a centre, runs merged */
        PickCam *c = &cams[k];
        int64_t lo[PICK_MAX_CAMS + 1], hi[PICK_MAX_CAMS + 1];
        int runs = 0;
        for (int j = 0; j <= n; j++) { /* each centre's run, kept in order of start (insertion) */
            int64_t start = bisect_left(c, extended, centres[j] - radius);
            int64_t stop = bisect_right(c, extended, centres[j] + radius);
            if (start == stop)
                continue;
            int r = runs++;
            for (; r > 0 && lo[r - 1] > start; r--) {
                lo[r] = lo[r - 1];
                hi[r] = hi[r - 1];
            }
            lo[r] = start;
            hi[r] = stop;
        }
        int64_t emitted = 0; /* every index below this one is in events already */
        for (int r = 0; r < runs; r++) {
            int64_t start = lo[r] > emitted ? lo[r] : emitted;
            if (hi[r] - start > PICK_MAX_EVENTS - n_events)
                return PICK_UNSUPPORTED;
            for (int64_t i = start; i < hi[r]; i++)
                events[n_events++] = (Event){at(c, i), i, c->rank, k};
            if (hi[r] > emitted)
                emitted = hi[r];
        }
    }
    qsort(events, (size_t)n_events, sizeof(Event), by_time_name_index);
    /* Two pointers: for every right end, the shortest window holding every camera. */
    int inside[PICK_MAX_CAMS] = {0}, distinct = 0, left = 0, windows = 0;
    for (int right = 0; right < n_events; right++) {
        if (inside[events[right].cam]++ == 0)
            distinct++;
        while (distinct == n) {
            int left_cam = events[left].cam;
            if (inside[left_cam] == 1)
                break;
            inside[left_cam]--;
            left++;
        }
        if (distinct == n) {
            starts[windows] = left;
            ends[windows] = right;
            windows++;
        }
    }
    int64_t best_skew = INT64_MAX;
    for (int w = 0; w < windows; w++)
        if (events[ends[w]].t - events[starts[w]].t < best_skew)
            best_skew = events[ends[w]].t - events[starts[w]].t;
    int found = 0;
    int64_t best_error = 0, best_tuple_skew = 0;
    for (int w = 0; w < windows; w++) {
        if (events[ends[w]].t - events[starts[w]].t > best_skew + tolerance)
            continue;
        /* each camera's frame in the window closest to t*; the newest wins ties */
        Selection here;
        int64_t dist[PICK_MAX_CAMS];
        int seen[PICK_MAX_CAMS] = {0};
        for (int e = starts[w]; e <= ends[w]; e++) {
            const Event *ev = &events[e];
            int64_t d = distance(ev->t, t_star);
            if (!seen[ev->cam] || d <= dist[ev->cam]) {
                here.index[ev->cam] = ev->i;
                here.t[ev->cam] = ev->t;
                dist[ev->cam] = d;
                seen[ev->cam] = 1;
            }
        }
        int64_t error = 0;
        for (int k = 0; k < n; k++)
            if (dist[k] > error)
                error = dist[k];
        int64_t skew = skew_of(&here, n);
        if (!found || error < best_error || (error == best_error && skew <= best_tuple_skew)) {
            *s = here;
            found = 1;
            best_error = error;
            best_tuple_skew = skew;
        }
    }
    s->least_skew = best_skew;
    return PICK_PLAN;
}

static int choose(PickCam *cams, int n, int joint, int extended, int64_t t_star, int64_t radius, int64_t tolerance,
                  Selection *s) {
    if (!joint) {
        select_independent(cams, n, extended, t_star, s);
        return PICK_PLAN;
    }
    return select_joint(cams, n, extended, t_star, radius, tolerance, s);
}

/* on_grid's test: do the chosen lockstep frames come from different grid points? */
static int off_grid(PickCam *cams, int n, const Selection *s) {
    int64_t point = 0;
    for (int k = 0; k < n; k++) {
        int64_t g = cams[k].grid == NULL ? 0 : cams[k].grid(&cams[k], s->index[k]);
        if (g != 0 && point != 0 && g != point)
            return 1;
        if (g != 0)
            point = g;
    }
    return 0;
}

/* ---- waitpolicy.py ---- */

/* with_predictions: the frames the camera should still deliver up to `up_to`, not yet overdue. */
static int predict(PickCam *c, int64_t now, int64_t up_to) {
    c->n_predicted = 0;
    if (c->stored == 0 || c->period_ns <= 0)
        return PICK_PLAN;
    int64_t steps = 0;
    for (int64_t t = c->read(c, c->stored - 1) + c->period_ns; t <= up_to; t += c->period_ns) {
        if (++steps > MAX_STEPS)
            return PICK_UNSUPPORTED;
        if (now < t + c->period_ns + c->delay_ns) { /* overdue_time: then taken as dropped */
            if (c->n_predicted == PICK_MAX_PREDICTED)
                return PICK_UNSUPPORTED;
            c->predicted[c->n_predicted++] = t;
        }
    }
    return PICK_PLAN;
}

/* waiting_for_selection: PICK_WAIT (marking the cameras) if the best selection over stored
 * and predicted frames has a frame still to come, and the stored one is not as good. */
static int auto_wait(PickCam *cams, int n, int joint, const PickRequest *r, int64_t radius, int64_t tolerance,
                     const Selection *stored) {
    int any_predicted = 0, status;
    for (int k = 0; k < n; k++) {
        if ((status = predict(&cams[k], r->now, r->t_star + radius)) != PICK_PLAN)
            return status;
        any_predicted |= cams[k].n_predicted > 0;
    }
    if (!any_predicted)
        return PICK_PLAN;
    Selection chosen;
    if ((status = choose(cams, n, joint, 1, r->t_star, radius, tolerance, &chosen)) != PICK_PLAN)
        return status;
    int future = 0;
    for (int k = 0; k < n; k++)
        future |= cams[k].waits = chosen.index[k] >= cams[k].stored;
    if (!future)
        return PICK_PLAN;
    /* predicted frames carry no jitter: a tuple of them nearer by less than the tolerance may not be */
    int as_near = max_abs_error(stored, n, r->t_star) < max_abs_error(&chosen, n, r->t_star) + tolerance;
    if (as_near && skew_of(stored, n) <= skew_of(&chosen, n) + 2 * tolerance)
        return PICK_PLAN;
    return PICK_WAIT;
}

/* ---- decisions._near ---- */

static int failed_read(const PickCam *cams, int n) {
    for (int k = 0; k < n; k++)
        if (cams[k].failed)
            return 1;
    return 0;
}

static int decide(PickCam *cams, int n, const PickRequest *r, PickResult *result) {
    int64_t radius = 0, tolerance = r->tolerance_setting_ns, shortest = 0; /* radius_for, tolerance_for */
    for (int k = 0; k < n; k++) {
        cams[k].waits = 0;
        if (cams[k].period_ns > radius)
            radius = cams[k].period_ns;
        if (cams[k].period_ns > 0 && (shortest == 0 || cams[k].period_ns < shortest))
            shortest = cams[k].period_ns;
    }
    if (shortest > 0 && shortest / 4 < tolerance)
        tolerance = shortest / 4;
    int joint = r->tuple && r->joint, status;
    Selection sel = {.least_skew = -1};
    if (r->wait_auto) {
        int empty = 0;
        for (int k = 0; k < n; k++)
            empty |= cams[k].waits = cams[k].stored == 0;
        if (empty)
            return PICK_WAIT;
        if ((status = choose(cams, n, joint, 0, r->t_star, radius, tolerance, &sel)) != PICK_PLAN)
            return status;
        if ((status = auto_wait(cams, n, joint, r, radius, tolerance, &sel)) != PICK_PLAN)
            return status;
    }
    for (int k = 0; k < n; k++) { /* check_not_empty */
        if (cams[k].stored == 0) {
            result->reject = "NO_FRAMES";
            return PICK_REJECT;
        }
    }
    for (int k = 0; r->check_history && k < n; k++) { /* check_history: over half a period older */
        if (2 * (at(&cams[k], 0) - r->t_star) > cams[k].period_ns) {
            result->reject = "OUT_OF_RANGE";
            return PICK_REJECT;
        }
    }
    if (!r->wait_auto && (status = choose(cams, n, joint, 0, r->t_star, radius, tolerance, &sel)) != PICK_PLAN)
        return status;
    if (off_grid(cams, n, &sel))
        return PICK_UNSUPPORTED;
    if (r->tuple && r->max_skew_ns >= 0 && (double)skew_of(&sel, n) > r->max_skew_ns) {
        if ((double)best_skew_of(&sel, n) <= r->max_skew_ns) {
            if ((status = choose(cams, n, joint, 0, r->t_star, radius, 0, &sel)) != PICK_PLAN)
                return status;
            if (off_grid(cams, n, &sel))
                return PICK_UNSUPPORTED;
        }
        if ((double)skew_of(&sel, n) > r->max_skew_ns) {
            result->reject = "SKEW_EXCEEDED";
            return PICK_REJECT;
        }
    }
    for (int k = 0; k < n; k++) {
        cams[k].index = sel.index[k];
        cams[k].t = sel.t[k];
    }
    result->skew_ns = skew_of(&sel, n);
    return PICK_PLAN;
}

int pick_near(PickCam *cams, int n, const PickRequest *request, PickResult *result) {
    if (n < 1 || n > PICK_MAX_CAMS)
        return PICK_UNSUPPORTED;
    for (int k = 0; k < n; k++)
        cams[k].failed = 0;
    result->reject = NULL;
    result->skew_ns = 0;
    int status = decide(cams, n, request, result);
    return failed_read(cams, n) ? PICK_UNREAD : status;
}
