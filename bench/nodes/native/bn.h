/* The native node loop's library: transports, the period clock and its counters.
 *
 * No allocation after the open/init calls: every buffer is in the structs
 * below or given by the caller.  Layout and what is left: __init__.py beside
 * this file.
 *
 *   bn_frame_t       one CAN or CAN FD frame (what both transports carry)
 *   bn_bus_t         a transport: python-can's udp_multicast wire format
 *                    (bn_udp_open) or a SocketCAN raw socket (bn_can_open)
 *   bn_mp_pack/unpack the udp_multicast datagram: python-can's msgpack map
 *   bn_clock_t       absolute CLOCK_MONOTONIC deadlines (clock_nanosleep
 *                    TIMER_ABSTIME) with an optional busy-wait tail, missed
 *                    deadlines and busy time per period
 *   bn_rt_apply      SCHED_FIFO, mlockall, CPU pin; what was granted
 *   bn_timing_run    the clock alone for N periods (measurement and tests)
 */
#ifndef BN_H
#define BN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>
#include <sys/uio.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- frames ------------------------------------------------------------ */

#define BN_MAX_DATA 64

enum {
    BN_EXT = 1u << 0, /* 29-bit identifier */
    BN_FD = 1u << 1,  /* CAN FD frame */
    BN_BRS = 1u << 2, /* FD bit-rate switch */
    BN_ESI = 1u << 3, /* FD error state indicator */
    BN_RTR = 1u << 4, /* remote frame */
    BN_ERR = 1u << 5  /* error frame */
};

typedef struct {
    uint32_t id;                /* identifier, without flag bits */
    uint8_t len;                /* payload bytes, 0..64 */
    uint8_t flags;              /* BN_* */
    uint8_t data[BN_MAX_DATA];
    int64_t t_ns;               /* receive time, CLOCK_REALTIME ns (0: unknown) */
} bn_frame_t;

/* ---- signal tables ---------------------------------------------------------
 * Encode-side description of one signal, as bench.wire._codec's _Sig, and the
 * decode-side range check (chk_lo > chk_hi: not checked): one row of
 * bench.wire._codec.Codec.signal_table, filled by Python from its codec, so no
 * DBC fact is written in C.  The plant unit (bn_plant.h) and the controller
 * unit (bn_ctl.h) both take their tables in it (ctypes: _native.Sig). */
typedef struct {
    double lo, hi, scale, offset;
    int64_t modulus;
    double chk_lo, chk_hi;
} bn_sig_t;

/* ---- python-can udp_multicast wire format ---------------------------------
 * One datagram per frame: a msgpack map of the eleven keys python-can's
 * can/interfaces/udp_multicast/utils.py pack_message writes (timestamp,
 * arbitration_id, is_extended_id, is_remote_frame, is_error_frame, channel,
 * dlc, data, is_fd, bitrate_switch, error_state_indicator).  */

/* Room for the longest datagram bn_mp_pack writes (64 data bytes: 220 bytes). */
#define BN_MP_MAX 256

/* Pack f into out (cap bytes); the number of bytes, 0 when cap is too small. */
size_t bn_mp_pack(const bn_frame_t *f, double timestamp_s, uint8_t *out, size_t cap);

/* Unpack a datagram; 0, or -1 when it is not a python-can message (unknown
 * msgpack type, truncated, data longer than 64 bytes).  Unknown keys are
 * skipped; a missing key keeps python-can's default (False, 0, no data). */
int bn_mp_unpack(const uint8_t *in, size_t n, bn_frame_t *f);

/* ---- transports ---------------------------------------------------------- */

enum { BN_BUS_UDP = 1, BN_BUS_CAN = 2 };

/* Datagrams or frames taken from the socket by one recvmmsg, and sent by one
 * sendmmsg (bn_send_many).  A 10 kHz period of the plant sees its own 3-5
 * looped-back frames and the controller's 2; 16 drains a period in one call. */
#define BN_BATCH 16
#define BN_DGRAM (BN_MP_MAX + 64) /* room for one datagram (a longer one is malformed) */

typedef struct {
    int kind;                       /* BN_BUS_UDP or BN_BUS_CAN */
    int fd;                         /* socket, -1 when closed */
    int tx_fd;                      /* UDP: the socket sending (-1: fd sends), see bn_udp_open */
    bool tx_connected;              /* UDP: tx_fd is connect()ed to dest (sends name no address) */
    bool can_fd;                    /* SocketCAN: CAN_RAW_FD_FRAMES granted */
    struct sockaddr_storage dest;   /* UDP: the group and port */
    socklen_t dest_len;
    uint8_t buf[BN_DGRAM];          /* UDP datagram being sent */
    int64_t send_wait_ns;           /* bn_send waits this long for room (open: 1 ms) */
    /* the receive batch: rx_n datagrams of the last recvmmsg, rx_i handed out,
     * drained at rx_t_ns (CLOCK_REALTIME); each frame's t_ns is the kernel's receive
     * stamp (SO_TIMESTAMPNS, in rx_ctl, as python-can's), else rx_t_ns */
    int32_t rx_n, rx_i;
    int64_t rx_t_ns;
    uint8_t rx_buf[BN_BATCH][BN_DGRAM];
    struct mmsghdr rx_msg[BN_BATCH];
    struct iovec rx_iov[BN_BATCH];
    uint64_t rx_ctl[BN_BATCH][8];
    /* the send batch of bn_send_many; UDP without tx_fd: its tx_n datagrams, looped
     * back to this socket by the kernel, are dropped on receipt undecoded (rx_own) */
    int32_t tx_n;
    uint8_t tx_buf[BN_BATCH][BN_DGRAM];
    struct mmsghdr tx_msg[BN_BATCH];
    struct iovec tx_iov[BN_BATCH];
    /* counters */
    uint64_t rx, tx, rx_malformed, tx_errors, tx_waits, rx_own;
} bn_bus_t;

/* sizeof(bn_bus_t): the room Python allocates for one. */
size_t bn_bus_size(void);

/* The hop limit (IPv6) or TTL (IPv4) the native nodes send with: the bench's one
 * value, UDP_HOP_LIMIT of bench/wire/_bus.py (0, this host: why there), which the
 * build passes as -DBN_UDP_HOPS (bench/nodes/native/_native.py CFLAGS). */
#ifndef BN_UDP_HOPS
#error "BN_UDP_HOPS: build with -DBN_UDP_HOPS=<bench.wire._bus.UDP_HOP_LIMIT>"
#endif

/* Join python-can's udp_multicast bus: group (IPv6 "ff15:..." or IPv4
 * "239.74.163.2"), port; send with hop limit / TTL BN_UDP_HOPS.  SO_REUSEADDR
 * and SO_REUSEPORT as python-can sets them, so python-can nodes share the port.
 * rcvbuf: receive buffer asked for (bytes, 0: the system's).  The datagrams
 * are sent from a second socket (tx_fd, an ephemeral source port), and a
 * socket filter on the receiving one drops the kernel's loop-back copies of
 * them (that source port) before they are queued; where either cannot be
 * had, fd sends and the copies are dropped after reading (rx_own).  The
 * sending socket is connect()ed to the group (tx_connected), so the kernel
 * routes a datagram without a lookup of its own.
 * 0 or -errno. */
int bn_udp_open(bn_bus_t *b, const char *group, uint16_t port, int rcvbuf);

/* A SocketCAN raw socket on ifname (vcan0, can0); fd: also CAN FD frames
 * (CAN_RAW_FD_FRAMES; -EPROTONOSUPPORT... when the kernel or device refuses).
 * Own frames are not looped back to this socket.  0 or -errno. */
int bn_can_open(bn_bus_t *b, const char *ifname, bool fd);

/* Send one frame.  A full socket (EAGAIN, ENOBUFS: the kernel has not yet
 * freed the datagrams or frames sent before) is waited on for at most
 * b->send_wait_ns; python-can's send blocks instead.  0, or -errno (the frame
 * is counted in tx_errors; a wait is counted in tx_waits). */
int bn_send(bn_bus_t *b, const bn_frame_t *f);

/* Send n frames with one sendmmsg (UDP; SocketCAN: one write each); the
 * number of frames the socket took, from the first, without waiting (a full
 * socket, an error: the caller sends the rest with bn_send). */
int bn_send_many(bn_bus_t *b, const bn_frame_t *f, int n);

/* Receive one frame, waiting no later than deadline_ns (CLOCK_MONOTONIC ns;
 * 0: do not wait).  1 a frame, 0 none by the deadline, -errno on an error.
 * Malformed datagrams are counted and skipped.  The socket is drained by
 * recvmmsg, up to BN_BATCH datagrams per call; the frames of one call carry
 * its time. */
int bn_recv_until(bn_bus_t *b, bn_frame_t *f, int64_t deadline_ns);

/* bn_recv_until with a relative timeout (ns; 0: do not wait). */
int bn_recv(bn_bus_t *b, bn_frame_t *f, int64_t timeout_ns);

void bn_close(bn_bus_t *b);

/* ---- frames held for Python ------------------------------------------------
 * Real time: the frames a node loop hands to Python (BenchCommand), held from where
 * the loop met them (before a step: the plant; while a sample may wait: the
 * controller) to the slack of its period (bn_plant_loop.c, bn_ctl.c).  Size: a burst
 * of the bench's pacer, 32 commands (bench.runs._pacing.COMMAND_BURST) twice each,
 * met in one period. */
#define BN_HELD 64

typedef struct {
    uint64_t total, max, full; /* frames held, the most at once, handed over at once (full) */
    int32_t n, head;
    bn_frame_t f[BN_HELD];
} bn_held_t;

/* Hold *f: 0; when the ring is full the oldest goes to *out first (1: hand *out to
 * Python now; nothing is lost and the order is kept). */
int bn_held_put(bn_held_t *h, const bn_frame_t *f, bn_frame_t *out);

/* The oldest held frame into *out (h->n > 0). */
void bn_held_take(bn_held_t *h, bn_frame_t *out);

/* ---- time ---------------------------------------------------------------- */

int64_t bn_now_ns(void);       /* CLOCK_MONOTONIC */
int64_t bn_realtime_ns(void);  /* CLOCK_REALTIME */

/* Real-time settings asked for and granted (errno of each refusal, 0: granted). */
typedef struct {
    int32_t priority;       /* SCHED_FIFO priority asked for (0: none) */
    int32_t fifo;           /* 1 when SCHED_FIFO was granted */
    int32_t memory_locked;  /* 1 when mlockall succeeded */
    int32_t cpu;            /* CPU pinned to (-1: none) */
    int32_t err_sched, err_mlock, err_cpu;
} bn_rt_t;

/* SCHED_FIFO at priority (0: leave the class), mlockall (lock), pin to cpu
 * (-1: leave).  Fills *out; a refusal is not fatal. */
void bn_rt_apply(int priority, bool lock, int cpu, bn_rt_t *out);

/* What the clock counts, in a block Python reads with ctypes after the run
 * (bench/nodes/native/_native.py: Stats mirrors it field by field). */
typedef struct {
    uint64_t periods;        /* waits returned */
    uint64_t missed;         /* deadlines already passed when the period's work ended */
    uint64_t late_half;      /* wake-ups more than half a period after the deadline */
    uint64_t stalls;         /* wake-ups later than stall_ns (schedule moved on) */
    uint64_t skipped;        /* periods skipped by those moves */
    int64_t period_ns;
    int64_t wall_ns;         /* start to the last wake-up */
    int64_t late_min_ns;     /* earliest wake-up relative to its deadline (>= 0) */
    int64_t late_max_ns;
    int64_t busy_median_ns;  /* work per period: wake-up to the next wait */
    int64_t busy_max_ns;
    bn_rt_t rt;
} bn_stats_t;

typedef struct {
    int64_t period_ns, busy_tail_ns, stall_ns;
    int64_t t0_ns, woke_ns;
    uint64_t n;              /* deadlines passed: deadline k is t0 + (k + 1) T */
    bn_stats_t st;
    uint32_t *busy;          /* caller's buffer: busy ns of each period */
    size_t busy_cap;
} bn_clock_t;

/* A clock of period_ns; busy_tail_ns of spinning before each deadline (0:
 * sleep to it); a wake-up more than stall_ns late moves the schedule on by
 * the whole periods that passed (INT64_MAX: always catch up).  busy: caller's
 * buffer of busy_cap entries (the first busy_cap periods count in the median). */
void bn_clock_init(bn_clock_t *c, int64_t period_ns, int64_t busy_tail_ns, int64_t stall_ns,
                   uint32_t *busy, size_t busy_cap);

/* Start the schedule now: the first deadline is one period from now. */
void bn_clock_start(bn_clock_t *c);

/* The next deadline (CLOCK_MONOTONIC ns). */
int64_t bn_clock_deadline(const bn_clock_t *c);

/* End the period's work and wait for the next deadline; how late the wake-up
 * was (ns, >= 0).  A deadline that has passed counts as missed and returns
 * at once (the schedule stays absolute: the loop catches up). */
int64_t bn_clock_wait(bn_clock_t *c);

/* The counters with the busy median (sorts the caller's buffer: after the loop). */
void bn_clock_stats(bn_clock_t *c, bn_stats_t *out);

/* The clock alone: rt settings, then `periods` periods, each spinning work_ns
 * (0: none) before it waits; the previous scheduling class, affinity and
 * memory lock are restored afterwards.  busy: `periods` entries.  0 or -errno. */
typedef struct {
    int64_t period_ns, busy_tail_ns, stall_ns, work_ns;
    uint64_t periods;
    int32_t rt_priority, lock_memory, cpu;
} bn_timing_cfg_t;

int bn_timing_run(const bn_timing_cfg_t *cfg, uint32_t *busy, bn_stats_t *out);

/* ---- copies of a bench command (bn_cmdseen.c) ------------------------------
 * Each BenchCommand comes three times (twice at once, once more after
 * bench.runs._pacing.AGAIN_S), and a frame a node's loop hands to Python costs a
 * return and a decode there, mid-period in real time, at the nodes' SCHED_FIFO
 * priority.  The copies are dropped here instead, under one condition that makes
 * the drop exactly what Python does with them: the loop keeps the last BN_CMD_SEEN
 * frames Python's CommandQueue took (bench/nodes/_counters.py: a new or late
 * command, the frames whose (apply step, seq) go into CommandQueue.recent), each
 * with the node's step when taken; a frame byte for byte one of them, received at
 * most `span` steps later, has the same unwrapped apply step and seq (the step
 * unwraps within half its modulus of the node's step, a taken one lies no more
 * than a quarter before it, CommandQueue's stale bound: span = modulus / 8 keeps
 * it inside) and that key is still among recent's 64 (BN_CMD_SEEN <= 64): a frame
 * CommandQueue counts as repeated, no more.  So the loop counts it (copies, added
 * to the node's duplicates, reason repeated_counter) and drops it.  A frame Python
 * refused (stale, a bad CRC) is never in the list: its copies still
 * go to Python (a full queue keeps the key: its copies are repeats there too). */
#define BN_CMD_SEEN 16

typedef struct {
    uint32_t id;                     /* BenchCommand's identifier; 0: keep nothing */
    int32_t n, head;                 /* frames kept, the next slot */
    int64_t span;                    /* steps a copy may come after its original */
    uint8_t len[BN_CMD_SEEN], flags[BN_CMD_SEEN];
    uint8_t data[BN_CMD_SEEN][8];
    int64_t k[BN_CMD_SEEN];          /* the node's step when Python took it */
    uint64_t copies;                 /* frames dropped as copies */
} bn_cmd_seen_t;

/* Keep nothing yet; id and span as above. */
void bn_cmd_seen_init(bn_cmd_seen_t *s, uint32_t id, int64_t span);
/* 1 when f is a copy of a frame kept (counted in copies), else 0; now: the node's step. */
int bn_cmd_seen_copy(bn_cmd_seen_t *s, const bn_frame_t *f, int64_t now);
/* Python took f (CommandQueue.recent has its key) at the node's step now. */
void bn_cmd_seen_take(bn_cmd_seen_t *s, const bn_frame_t *f, int64_t now);

#ifdef __cplusplus
}
#endif

#endif /* BN_H */
