/* The native recorder: a receive thread without the GIL that keeps every datagram
 * of python-can's udp_multicast bus, or every frame of a SocketCAN interface, with
 * its kernel receive stamp, in a ring preallocated at open (bn_rec.h).
 *
 * The thread blocks in ppoll on the socket and drains it with recvmmsg straight
 * into the ring's free slots (no copy, no allocation); Python takes the slots in
 * batches (bn_rec_take) and turns each into a can.Message as python-can's bus does
 * (udp_multicast: the fields bn_rec_parse reads from python-can's usual map, checked as
 * python-can's Message._check checks them, else its own unpack_message; SocketCAN: its
 * dissect_can_frame and the fields of its capture_message), so the capture holds what
 * python-can's bus would have returned.  A datagram that finds the ring full is counted (ring_lost) and its
 * slot reused; on SocketCAN the kernel's own drops for the socket are counted too
 * (SO_RXQ_OVFL): the loss is reported, never silent.
 */
#include <errno.h>
#include <stdbool.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <linux/can/raw.h>

#include "bn_rec.h"

/* Datagrams per recvmmsg: a 10 kHz native pair sends about 4 a period, so one call
 * takes what several periods sent when the thread was descheduled for a while. */
#define REC_BATCH 64

struct bn_rec {
    bn_bus_t bus; /* the socket (bn_udp_open); its own receive batch is not used */
    bn_rec_slot_t *ring;
    uint64_t cap;
    uint64_t head; /* written by the thread (slots filled), read by the taker */
    uint64_t tail; /* written by the taker (slots taken), read by the thread */
    int stop;
    int started;
    int priority;
    pthread_t thread;
    bn_rec_stats_t st;
    struct mmsghdr msg[REC_BATCH];
    struct iovec iov[REC_BATCH];
    uint64_t ctl[REC_BATCH][8];
    bn_rec_slot_t spare; /* where a datagram that finds the ring full is read */
};

size_t bn_rec_slot_size(void) { return sizeof(bn_rec_slot_t); }

/* The recorder with its ring (allocated and touched here: no page fault in the loop). */
static bn_rec_t *rec_alloc(uint64_t capacity, int priority, int *err)
{
    bn_rec_t *r = calloc(1, sizeof *r);
    if (r == NULL) {
        *err = -ENOMEM;
        return NULL;
    }
    r->cap = capacity < 1 ? 1 : capacity;
    r->ring = calloc(r->cap, sizeof *r->ring);
    if (r->ring == NULL) {
        free(r);
        *err = -ENOMEM;
        return NULL;
    }
    memset(r->ring, 0, r->cap * sizeof *r->ring);
    r->priority = priority;
    *err = 0;
    return r;
}

static bn_rec_t *rec_fail(bn_rec_t *r, int e, int *err)
{
    free(r->ring);
    free(r);
    *err = e;
    return NULL;
}

bn_rec_t *bn_rec_open(const char *group, uint16_t port, int rcvbuf, uint64_t capacity,
                      int priority, int *err)
{
    bn_rec_t *r = rec_alloc(capacity, priority, err);
    if (r == NULL) {
        return NULL;
    }
    int e = bn_udp_open(&r->bus, group, port, rcvbuf);
    if (e != 0) {
        return rec_fail(r, e, err);
    }
    r->st.fd = r->bus.fd;
    r->st.kind = BN_BUS_UDP;
    return r;
}

bn_rec_t *bn_rec_open_can(const char *ifname, int fd, int rcvbuf, uint64_t capacity,
                          int priority, int *err)
{
    bn_rec_t *r = rec_alloc(capacity, priority, err);
    if (r == NULL) {
        return NULL;
    }
    int e = bn_can_open(&r->bus, ifname, fd != 0);
    if (e != 0) {
        return rec_fail(r, e, err);
    }
    int one = 1;
    /* the kernel's count of the frames it dropped for this socket, with each frame */
    (void)setsockopt(r->bus.fd, SOL_SOCKET, SO_RXQ_OVFL, &one, sizeof one);
    if (rcvbuf > 0 &&
        setsockopt(r->bus.fd, SOL_SOCKET, SO_RCVBUFFORCE, &rcvbuf, sizeof rcvbuf) != 0) {
        (void)setsockopt(r->bus.fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
    }
    r->st.fd = r->bus.fd;
    r->st.kind = BN_BUS_CAN;
    return r;
}

/* The kernel's receive stamp (SO_TIMESTAMPNS) of one datagram into its slot, and its
 * count of the socket's drops (SO_RXQ_OVFL, SocketCAN) into the counters. */
static void stamp(bn_rec_t *r, struct msghdr *h, bn_rec_slot_t *s)
{
    s->sec = -1;
    s->nsec = 0;
    for (struct cmsghdr *c = CMSG_FIRSTHDR(h); c != NULL; c = CMSG_NXTHDR(h, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS) {
            struct timespec ts;
            memcpy(&ts, CMSG_DATA(c), sizeof ts);
            s->sec = (int64_t)ts.tv_sec;
            s->nsec = (int64_t)ts.tv_nsec;
        } else if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SO_RXQ_OVFL) {
            uint32_t drops;
            memcpy(&drops, CMSG_DATA(c), sizeof drops);
            __atomic_store_n(&r->st.kernel_drops, (uint64_t)drops, __ATOMIC_RELAXED);
        }
    }
    s->local = (h->msg_flags & MSG_DONTROUTE) != 0;
}

/* Drain the socket once: the datagrams taken, 0 (none), -errno. */
static int drain_once(bn_rec_t *r)
{
    uint64_t head = r->head;
    uint64_t tail = __atomic_load_n(&r->tail, __ATOMIC_ACQUIRE);
    uint64_t room = r->cap - (head - tail);
    int n = 0;
    bool full = room == 0;
    if (full) {
        /* read one into the spare slot: the kernel's buffer must not fill behind a full ring */
        r->iov[0].iov_base = r->spare.data;
        r->iov[0].iov_len = sizeof r->spare.data;
        n = 1;
    } else {
        /* the free slots up to the ring's end, at most a batch */
        uint64_t at = head % r->cap;
        uint64_t run = r->cap - at;
        if (run > room) {
            run = room;
        }
        n = run > REC_BATCH ? REC_BATCH : (int)run;
        for (int j = 0; j < n; j++) {
            r->iov[j].iov_base = r->ring[at + (uint64_t)j].data;
            r->iov[j].iov_len = sizeof r->ring[0].data;
        }
    }
    for (int j = 0; j < n; j++) {
        memset(&r->msg[j].msg_hdr, 0, sizeof r->msg[j].msg_hdr);
        r->msg[j].msg_hdr.msg_iov = &r->iov[j];
        r->msg[j].msg_hdr.msg_iovlen = 1;
        r->msg[j].msg_hdr.msg_control = r->ctl[j];
        r->msg[j].msg_hdr.msg_controllen = sizeof r->ctl[j];
    }
    int got = recvmmsg(r->bus.fd, r->msg, (unsigned)n, MSG_DONTWAIT, NULL);
    if (got < 0) {
        return (errno == EAGAIN || errno == EWOULDBLOCK) ? 0 : -errno;
    }
    if (full) {
        __atomic_fetch_add(&r->st.ring_lost, (uint64_t)got, __ATOMIC_RELAXED);
        return got;
    }
    uint64_t at = head % r->cap;
    for (int j = 0; j < got; j++) {
        bn_rec_slot_t *s = &r->ring[at + (uint64_t)j];
        stamp(r, &r->msg[j].msg_hdr, s);
        s->len = (uint16_t)r->msg[j].msg_len;
        s->truncated = (r->msg[j].msg_hdr.msg_flags & MSG_TRUNC) != 0;
    }
    __atomic_fetch_add(&r->st.received, (uint64_t)got, __ATOMIC_RELAXED);
    __atomic_store_n(&r->head, head + (uint64_t)got, __ATOMIC_RELEASE);
    return got;
}

static void *run(void *arg)
{
    bn_rec_t *r = arg;
    (void)pthread_setname_np(pthread_self(), "bn-recorder"); /* its line in top, /proc */
    if (r->priority > 0) {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = r->priority;
        int e = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
        r->st.fifo = e == 0;
        r->st.err_sched = e;
    }
    while (!__atomic_load_n(&r->stop, __ATOMIC_ACQUIRE)) {
        int got = drain_once(r);
        r->st.calls++;
        if (got < 0) {
            r->st.errors++;
        }
        if (got == REC_BATCH) {
            continue; /* more may wait */
        }
        if (got > 0) {
            /* the socket is empty: let the next datagrams gather for a while (one
             * recvmmsg for them, not one wake-up each) */
            struct timespec nap = {0, BN_REC_NAP_NS};
            (void)clock_nanosleep(CLOCK_MONOTONIC, 0, &nap, NULL);
            continue;
        }
        /* empty: wait for the next datagram, looking at the stop flag each poll period */
        struct pollfd p = {r->bus.fd, POLLIN, 0};
        struct timespec ts = {0, BN_REC_POLL_NS};
        (void)ppoll(&p, 1, &ts, NULL);
    }
    struct timespec cpu;
    if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &cpu) == 0) {
        r->st.cpu_ns = (int64_t)cpu.tv_sec * 1000000000 + cpu.tv_nsec;
    }
    return NULL;
}

int bn_rec_start(bn_rec_t *r)
{
    if (r->started) {
        return 0;
    }
    int e = pthread_create(&r->thread, NULL, run, r);
    if (e != 0) {
        return -e;
    }
    r->started = 1;
    return 0;
}

uint64_t bn_rec_take(bn_rec_t *r, bn_rec_slot_t *out, uint64_t max)
{
    uint64_t tail = r->tail;
    uint64_t head = __atomic_load_n(&r->head, __ATOMIC_ACQUIRE);
    uint64_t n = head - tail;
    if (n > max) {
        n = max;
    }
    for (uint64_t k = 0; k < n; k++) {
        out[k] = r->ring[(tail + k) % r->cap];
    }
    __atomic_store_n(&r->tail, tail + n, __ATOMIC_RELEASE);
    return n;
}

uint64_t bn_rec_pending(bn_rec_t *r)
{
    uint64_t head = __atomic_load_n(&r->head, __ATOMIC_ACQUIRE);
    uint64_t tail = __atomic_load_n(&r->tail, __ATOMIC_ACQUIRE); /* another thread takes */
    int queued = 0;
    if (ioctl(r->bus.fd, FIONREAD, &queued) != 0) {
        queued = 0;
    }
    return (head - tail) + (queued > 0 ? 1u : 0u);
}

void bn_rec_stop(bn_rec_t *r)
{
    if (r->started) {
        __atomic_store_n(&r->stop, 1, __ATOMIC_RELEASE);
        pthread_join(r->thread, NULL);
        r->started = 0;
        /* counted, and their SO_RXQ_OVFL read: the kernel's drops before the last of them */
        bn_rec_slot_t *s = &r->spare;
        for (;;) {
            struct iovec iov = {s->data, sizeof s->data};
            struct msghdr h;
            memset(&h, 0, sizeof h);
            h.msg_iov = &iov;
            h.msg_iovlen = 1;
            h.msg_control = r->ctl[0];
            h.msg_controllen = sizeof r->ctl[0];
            if (recvmsg(r->bus.fd, &h, MSG_DONTWAIT) < 0) {
                break;
            }
            stamp(r, &h, s);
            r->st.unread++;
        }
    }
}

void bn_rec_stats(const bn_rec_t *r, bn_rec_stats_t *out)
{
    *out = r->st; /* the other counters are final once the thread has stopped */
    out->received = __atomic_load_n(&r->st.received, __ATOMIC_RELAXED);
    out->ring_lost = __atomic_load_n(&r->st.ring_lost, __ATOMIC_RELAXED);
    out->kernel_drops = __atomic_load_n(&r->st.kernel_drops, __ATOMIC_RELAXED);
}

void bn_rec_close(bn_rec_t *r)
{
    if (r == NULL) {
        return;
    }
    bn_rec_stop(r);
    bn_close(&r->bus);
    free(r->ring);
    free(r);
}

/* ---- python-can's datagram, parsed where it has its usual shape ---- */

size_t bn_rec_frame_size(void) { return sizeof(bn_rec_frame_t); }

typedef struct {
    const uint8_t *p;
    size_t n, i;
} mp_t;

/* The fixstr key s next (exactly). */
static bool mp_key(mp_t *m, const char *s)
{
    size_t len = strlen(s);
    if (m->i + 1 + len > m->n || m->p[m->i] != (uint8_t)(0xa0u | len) ||
        memcmp(m->p + m->i + 1, s, len) != 0) {
        return false;
    }
    m->i += 1 + len;
    return true;
}

/* A msgpack bool (Python bool, not an int standing for one). */
static bool mp_bool(mp_t *m, bool *v)
{
    if (m->i >= m->n || (m->p[m->i] != 0xc2u && m->p[m->i] != 0xc3u)) {
        return false;
    }
    *v = m->p[m->i++] == 0xc3u;
    return true;
}

/* A msgpack unsigned integer up to 32 bits (positive fixint, uint 8/16/32). */
static bool mp_uint(mp_t *m, uint32_t *v)
{
    if (m->i >= m->n) {
        return false;
    }
    uint8_t c = m->p[m->i++];
    int bytes;
    if (c <= 0x7fu) {
        *v = c;
        return true;
    }
    if (c == 0xccu) {
        bytes = 1;
    } else if (c == 0xcdu) {
        bytes = 2;
    } else if (c == 0xceu) {
        bytes = 4;
    } else {
        return false;
    }
    if (m->i + (size_t)bytes > m->n) {
        return false;
    }
    uint32_t x = 0;
    for (int k = 0; k < bytes; k++) {
        x = (x << 8) | m->p[m->i++];
    }
    *v = x;
    return true;
}

/* One datagram: 1 and the fields of python-can's message, or 0 (python-can decides). */
static int parse_one(const uint8_t *p, size_t n, bn_rec_frame_t *f)
{
    mp_t m = {p, n, 0};
    bool ext, rtr, err, fd, brs, esi;
    uint32_t id, dlc;
    memset(f, 0, sizeof *f);
    if (n < 1 || p[0] != (0x80u | 11u)) { /* fixmap of 11 */
        return 0;
    }
    m.i = 1;
    /* the timestamp is replaced by the receive stamp: any float will do */
    if (!mp_key(&m, "timestamp") || m.i >= n) {
        return 0;
    }
    if (p[m.i] == 0xcbu) {
        m.i += 9;
    } else if (p[m.i] == 0xcau) {
        m.i += 5;
    } else {
        return 0;
    }
    if (m.i > n || !mp_key(&m, "arbitration_id") || !mp_uint(&m, &id) ||
        !mp_key(&m, "is_extended_id") || !mp_bool(&m, &ext) ||
        !mp_key(&m, "is_remote_frame") || !mp_bool(&m, &rtr) ||
        !mp_key(&m, "is_error_frame") || !mp_bool(&m, &err) || !mp_key(&m, "channel") ||
        m.i >= n) {
        return 0;
    }
    if (p[m.i] == 0xc0u) { /* None */
        m.i++;
    } else if (mp_uint(&m, &f->channel)) {
        f->has_channel = 1;
    } else {
        return 0; /* a str (python-can decodes it) */
    }
    if (!mp_key(&m, "dlc") || !mp_uint(&m, &dlc) ||
        !mp_key(&m, "data") || m.i + 2 > n || p[m.i] != 0xc4u) {
        return 0;
    }
    size_t len = p[m.i + 1];
    size_t off = m.i + 2;
    m.i = off + len;
    if (m.i > n || !mp_key(&m, "is_fd") || !mp_bool(&m, &fd) || !mp_key(&m, "bitrate_switch") ||
        !mp_bool(&m, &brs) || !mp_key(&m, "error_state_indicator") || !mp_bool(&m, &esi) ||
        m.i != n) {
        return 0;
    }
    /* python-can's Message._check, for the message it would build (a remote frame is left
     * to python-can: its data is dropped) */
    if (rtr || id >= (ext ? 0x20000000u : 0x800u) || dlc > (fd ? 64u : 8u) || dlc != len ||
        (!fd && (brs || esi))) {
        return 0;
    }
    f->id = id;
    memcpy(f->data, p + off, len);
    f->off = (uint16_t)off;
    f->len = (uint8_t)len;
    f->flags = (uint8_t)((ext ? BN_EXT : 0) | (fd ? BN_FD : 0) | (brs ? BN_BRS : 0) |
                         (esi ? BN_ESI : 0) | (err ? BN_ERR : 0));
    f->ok = 1;
    return 1;
}

uint64_t bn_rec_parse(const bn_rec_slot_t *slots, uint64_t n, bn_rec_frame_t *out)
{
    uint64_t ok = 0;
    for (uint64_t k = 0; k < n; k++) {
        const bn_rec_slot_t *s = &slots[k];
        if (s->truncated) {
            memset(&out[k], 0, sizeof out[k]);
            continue;
        }
        ok += (uint64_t)parse_one(s->data, s->len, &out[k]);
    }
    return ok;
}
