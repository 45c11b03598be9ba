/* The native recorder (bn_rec.c): every datagram of python-can's udp_multicast bus, or
 * every frame of a SocketCAN interface, with the kernel's receive stamp, kept by a thread
 * of its own in a ring that Python empties in batches (bench/nodes/native/_recorder_native.py
 * mirrors these structs). */
#ifndef BN_REC_H
#define BN_REC_H

#include "bn.h"

#ifdef __cplusplus
extern "C" {
#endif

/* How long the thread waits for a datagram before it looks at its stop flag again
 * (ns): bn_rec_stop returns within about this long. */
#define BN_REC_POLL_NS 50000000L

/* After a receive call that emptied the socket, the thread sleeps this long (ns) before
 * the next one, so that the datagrams of about ten 10 kHz periods (some 40, fewer than
 * one recvmmsg batch of 64) come in one call rather than one wake-up each: its CPU time
 * per frame falls several-fold (docs/REALTIME.md), and the kernel's buffer (64 MB) and
 * the ring hold seconds of the bus, not one millisecond. */
#define BN_REC_NAP_NS 1000000L

/* One datagram (udp_multicast) or one struct can(fd)_frame (SocketCAN) as the socket
 * gave it. */
typedef struct {
    int64_t sec, nsec;        /* SO_TIMESTAMPNS receive stamp; sec -1: none */
    uint16_t len;             /* bytes of data (SocketCAN: CAN_MTU 16 or CANFD_MTU 72) */
    uint8_t truncated;        /* longer than data: malformed */
    uint8_t local;            /* SocketCAN: MSG_DONTROUTE, sent by a socket of this host */
    uint8_t pad[4];
    uint8_t data[BN_DGRAM];
} bn_rec_slot_t;

/* received and ring_lost may be read while the thread runs; the rest once it has stopped. */
typedef struct {
    uint64_t received;        /* datagrams put in the ring */
    uint64_t ring_lost;       /* datagrams read while the ring was full (dropped) */
    uint64_t unread;          /* datagrams still in the socket when it was closed */
    uint64_t errors;          /* failed receive calls */
    uint64_t calls;           /* receive calls (recvmmsg) */
    int64_t cpu_ns;           /* the thread's CPU time, when it has ended */
    int32_t fifo;             /* 1: the thread runs under SCHED_FIFO */
    int32_t err_sched;        /* errno of a refused SCHED_FIFO (0: granted or not asked) */
    int32_t fd;               /* the socket (for /proc/net/udp's drops) */
    int32_t kind;             /* BN_BUS_UDP or BN_BUS_CAN */
    uint64_t kernel_drops;    /* SocketCAN: frames the kernel dropped for the socket (its
                               * receive queue was full: SO_RXQ_OVFL's count, as of the
                               * last frame received); udp_multicast: 0, /proc/net/udp says */
} bn_rec_stats_t;

typedef struct bn_rec bn_rec_t;

size_t bn_rec_slot_size(void);

/* Join python-can's udp_multicast bus on group/port with a receive buffer of rcvbuf
 * bytes, and a ring of capacity datagrams (allocated and touched here); priority > 0:
 * the thread asks for SCHED_FIFO at it.  NULL with *err = -errno on failure. */
bn_rec_t *bn_rec_open(const char *group, uint16_t port, int rcvbuf, uint64_t capacity,
                      int priority, int *err);

/* Read SocketCAN interface ifname (CAN FD frames too when fd), with a receive buffer of
 * rcvbuf bytes (0: the system's default; as root beyond rmem_max), as bn_rec_open. */
bn_rec_t *bn_rec_open_can(const char *ifname, int fd, int rcvbuf, uint64_t capacity,
                          int priority, int *err);

/* Start the receive thread.  0 or -errno. */
int bn_rec_start(bn_rec_t *r);

/* Move up to max datagrams, oldest first, from the ring into out; how many. */
uint64_t bn_rec_take(bn_rec_t *r, bn_rec_slot_t *out, uint64_t max);

/* Datagrams in the ring, plus 1 when the socket holds any: 0 when all is taken. */
uint64_t bn_rec_pending(bn_rec_t *r);

/* Stop the thread (waits for it); then count and drop what is left in the socket. */
void bn_rec_stop(bn_rec_t *r);

void bn_rec_stats(const bn_rec_t *r, bn_rec_stats_t *out);

/* One datagram of python-can's udp_multicast bus as python-can's unpack_message would
 * turn it into a can.Message (check=True), where bn_rec_parse can say so exactly. */
typedef struct {
    uint32_t id;       /* arbitration_id */
    uint32_t channel;  /* channel, when has_channel (else None) */
    uint16_t off;      /* where data starts in the datagram */
    uint8_t len;       /* bytes of data (= dlc) */
    uint8_t flags;     /* BN_EXT, BN_FD, BN_BRS, BN_ESI, BN_ERR */
    uint8_t ok;        /* 1: the fields here are the message's; 0: not parsed here (another
                        * msgpack shape, a remote frame, or a message python-can's check
                        * refuses): python-can's own unpack_message decides */
    uint8_t has_channel; /* 1: channel is an int; 0: None */
    uint8_t pad[2];
    uint8_t data[BN_MAX_DATA]; /* the data, zero after len */
} bn_rec_frame_t;

size_t bn_rec_frame_size(void);

/* Parse n taken slots (bn_rec_take) into out[0..n): the map of the eleven keys in the
 * order python-can's pack_message writes them (channel nil or an unsigned int, data bin 8) whose values
 * pass python-can's Message._check.  How many were parsed (ok). */
uint64_t bn_rec_parse(const bn_rec_slot_t *slots, uint64_t n, bn_rec_frame_t *out);

/* Stop, close the socket and free the ring. */
void bn_rec_close(bn_rec_t *r);

#ifdef __cplusplus
}
#endif

#endif /* BN_REC_H */
