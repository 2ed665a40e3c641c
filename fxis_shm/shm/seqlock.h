/* What the C readers of a ring share (_slotio.c, _fastpick.c): the seqlock's ordered loads,
 * the read of a slot record, and the copy of a slot's bytes, each checked whole. */
#ifndef FXIS_SEQLOCK_H
#define FXIS_SEQLOCK_H

#include <stdatomic.h>
#include <stdint.h>
#include <string.h>
#if defined(__x86_64__)
#include <emmintrin.h>
#endif

static inline uint64_t load_acquire(const char *at) { return __atomic_load_n((const uint64_t *)at, __ATOMIC_ACQUIRE); }

static inline int64_t load_plain(const char *at) { return __atomic_load_n((const int64_t *)at, __ATOMIC_RELAXED); }

/* With ``stream``, a copy that goes to memory, not to this core's caches (SSE2 streaming
 * stores, on every x86-64): a frame of megabytes would not stay cached anyway, and a cached
 * copy first reads every destination line. Elsewhere (and below STREAM_MIN), memcpy. */
#define STREAM_MIN (512 * 1024)
static inline void copy_bytes(char *dst, const char *src, size_t n, int stream) {
#if defined(__x86_64__)
    if (stream && n >= STREAM_MIN) {
        size_t head = (16 - ((uintptr_t)dst & 15)) & 15, i;
        memcpy(dst, src, head);
        for (i = head; i + 64 <= n; i += 64) {
            __m128i a = _mm_loadu_si128((const __m128i *)(src + i));
            __m128i b = _mm_loadu_si128((const __m128i *)(src + i + 16));
            __m128i c = _mm_loadu_si128((const __m128i *)(src + i + 32));
            __m128i d = _mm_loadu_si128((const __m128i *)(src + i + 48));
            _mm_stream_si128((__m128i *)(dst + i), a);
            _mm_stream_si128((__m128i *)(dst + i + 16), b);
            _mm_stream_si128((__m128i *)(dst + i + 32), c);
            _mm_stream_si128((__m128i *)(dst + i + 48), d);
        }
        _mm_sfence(); /* the streamed stores are visible before anything after the copy */
        memcpy(dst + i, src + i, n - i);
        return;
    }
#else
    (void)stream;
#endif
    memcpy(dst, src, n);
}

/* A slot record (64 bytes: seq, then these), as a reader takes it. */
#define RECORD 64 /* seq, frame_id, t_capture, t_stored, t_available, generation, t_target, capture: 8 bytes each */
typedef struct {
    uint64_t frame_id, generation, capture;
    int64_t t_capture, t_stored, t_available, t_target;
} Record;

/* The record at `rec` if it showed `expected` (2w+2: write w, whole) before and after the read:
 * 0, else 1 (the fields are then not to be used). */
static inline int read_record(const char *rec, uint64_t expected, Record *out) {
    if (load_acquire(rec) != expected)
        return 1;
    out->frame_id = (uint64_t)load_plain(rec + 8);
    out->t_capture = load_plain(rec + 16);
    out->t_stored = load_plain(rec + 24);
    out->t_available = load_plain(rec + 32);
    out->generation = (uint64_t)load_plain(rec + 40);
    out->t_target = load_plain(rec + 48);
    out->capture = (uint64_t)load_plain(rec + 56);
    atomic_thread_fence(memory_order_acquire); /* the fields were read before seq is read again */
    return load_acquire(rec) != expected;
}

/* The seqlock read of a slot's `n` bytes into `dst`, `seq` its record's first word: 0 whole,
 * 1 overwritten before, 2 during (then `dst` holds nothing to use). */
static inline int copy_whole(const char *seq, uint64_t expected, char *dst, const char *src, size_t n, int stream) {
    if (load_acquire(seq) != expected)
        return 1;
    copy_bytes(dst, src, n, stream);
    atomic_thread_fence(memory_order_acquire); /* every byte was read before seq is read again */
    return load_acquire(seq) == expected ? 0 : 2;
}

#endif
