/* Transports of the native node loop: python-can's udp_multicast and SocketCAN raw.
 *
 * Both are non-blocking sockets; bn_recv_until waits with ppoll up to an
 * absolute CLOCK_MONOTONIC deadline, so a loop receives until its period
 * ends and never sleeps past it.
 */
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <linux/filter.h>
#include <net/if.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <string.h>
#include <sys/ioctl.h>
#include <time.h>
#include <unistd.h>

#include <linux/can.h>
#include <linux/can/raw.h>

#include "bn.h"

int64_t bn_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

int64_t bn_realtime_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

size_t bn_bus_size(void) { return sizeof(bn_bus_t); }

static void bus_reset(bn_bus_t *b, int kind)
{
    memset(b, 0, sizeof *b);
    b->kind = kind;
    b->fd = b->tx_fd = -1;
    b->send_wait_ns = 1000000;
    for (int j = 0; j < BN_BATCH; j++) { /* once: the batches' headers point at their buffers */
        b->rx_iov[j].iov_base = b->rx_buf[j];
        b->rx_iov[j].iov_len = sizeof b->rx_buf[j];
        b->rx_msg[j].msg_hdr.msg_iov = &b->rx_iov[j];
        b->rx_msg[j].msg_hdr.msg_iovlen = 1;
        b->rx_msg[j].msg_hdr.msg_control = b->rx_ctl[j];
        b->tx_iov[j].iov_base = b->tx_buf[j];
        b->tx_msg[j].msg_hdr.msg_iov = &b->tx_iov[j];
        b->tx_msg[j].msg_hdr.msg_iovlen = 1;
    }
}

static int fail(bn_bus_t *b)
{
    int e = errno;
    bn_close(b);
    return -e;
}

/* The sending socket of a UDP bus (bn_udp_open): bound to an ephemeral port, the
 * bus's hop limit; the receiving socket's filter drops what comes from that port
 * (the loop-back copies of this bus's own datagrams).  Best effort: on any refusal
 * tx_fd stays -1 and fd sends. */
static void open_sender(bn_bus_t *b, int family, int hop_limit)
{
    struct sockaddr_storage me;
    socklen_t n = sizeof me;
    int s = socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (s < 0) return;
    int sndbuf = 1 << 20;
    (void)setsockopt(s, SOL_SOCKET, SO_SNDBUFFORCE, &sndbuf, sizeof sndbuf);
    memset(&me, 0, sizeof me);
    me.ss_family = (sa_family_t)family;
    int ok = (family == AF_INET6
                  ? setsockopt(s, IPPROTO_IPV6, IPV6_MULTICAST_HOPS, &hop_limit, sizeof hop_limit)
                  : setsockopt(s, IPPROTO_IP, IP_MULTICAST_TTL, &hop_limit, sizeof hop_limit)) == 0 &&
             bind(s, (struct sockaddr *)&me,
                  family == AF_INET6 ? sizeof(struct sockaddr_in6) : sizeof(struct sockaddr_in)) ==
                 0 &&
             getsockname(s, (struct sockaddr *)&me, &n) == 0;
    if (ok) {
        uint16_t port = ntohs(family == AF_INET6 ? ((struct sockaddr_in6 *)&me)->sin6_port
                                                 : ((struct sockaddr_in *)&me)->sin_port);
        /* the filter sees the datagram from its UDP header: the source port first */
        struct sock_filter code[] = {
            BPF_STMT(BPF_LD | BPF_H | BPF_ABS, 0),
            BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, port, 0, 1),
            BPF_STMT(BPF_RET | BPF_K, 0),
            BPF_STMT(BPF_RET | BPF_K, 0xFFFFFFFFu),
        };
        struct sock_fprog prog = {(unsigned short)(sizeof code / sizeof code[0]), code};
        ok = setsockopt(b->fd, SOL_SOCKET, SO_ATTACH_FILTER, &prog, sizeof prog) == 0;
    }
    if (ok) {
        b->tx_fd = s;
        /* connected to the group: the kernel keeps the route and the destination on the
         * socket instead of looking them up for every datagram (sendmmsg of 4 datagrams,
         * IPv6, hop limit 0: 14 -> 11 us, docs/REALTIME.md); unconnected, dest is named */
        b->tx_connected = connect(s, (struct sockaddr *)&b->dest, b->dest_len) == 0;
    } else {
        close(s);
    }
}

int bn_udp_open(bn_bus_t *b, const char *group, uint16_t port, int rcvbuf)
{
    int one = 1, hop_limit = BN_UDP_HOPS;
    bool v6 = strchr(group, ':') != NULL;
    bus_reset(b, BN_BUS_UDP);
    b->fd = socket(v6 ? AF_INET6 : AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (b->fd < 0) {
        return fail(b);
    }
    if (setsockopt(b->fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) < 0 ||
        setsockopt(b->fd, SOL_SOCKET, SO_REUSEPORT, &one, sizeof one) < 0) {
        return fail(b);
    }
    /* a datagram's memory stays charged to this socket until the device has sent it;
     * a larger send buffer rides out a descheduled transmit completion */
    int sndbuf = 1 << 20;
    (void)setsockopt(b->fd, SOL_SOCKET, SO_SNDBUFFORCE, &sndbuf, sizeof sndbuf);
    /* receive stamps of the kernel, as python-can's (best effort: else the drain time) */
    (void)setsockopt(b->fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
    if (rcvbuf > 0 &&
        setsockopt(b->fd, SOL_SOCKET, SO_RCVBUFFORCE, &rcvbuf, sizeof rcvbuf) < 0) {
        (void)setsockopt(b->fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf); /* best effort */
    }
    if (v6) {
        struct sockaddr_in6 any, *dst = (struct sockaddr_in6 *)&b->dest;
        struct ipv6_mreq mreq;
        memset(&any, 0, sizeof any);
        any.sin6_family = AF_INET6;
        any.sin6_addr = in6addr_any;
        any.sin6_port = htons(port);
        memset(dst, 0, sizeof *dst);
        dst->sin6_family = AF_INET6;
        dst->sin6_port = htons(port);
        if (inet_pton(AF_INET6, group, &dst->sin6_addr) != 1) {
            errno = EINVAL;
            return fail(b);
        }
        b->dest_len = sizeof *dst;
        memset(&mreq, 0, sizeof mreq);
        mreq.ipv6mr_multiaddr = dst->sin6_addr;
        mreq.ipv6mr_interface = 0;
        if (setsockopt(b->fd, IPPROTO_IPV6, IPV6_MULTICAST_HOPS, &hop_limit, sizeof hop_limit) <
                0 ||
            bind(b->fd, (struct sockaddr *)&any, sizeof any) < 0 ||
            setsockopt(b->fd, IPPROTO_IPV6, IPV6_JOIN_GROUP, &mreq, sizeof mreq) < 0) {
            return fail(b);
        }
    } else {
        struct sockaddr_in any, *dst = (struct sockaddr_in *)&b->dest;
        struct ip_mreq mreq;
        memset(&any, 0, sizeof any);
        any.sin_family = AF_INET;
        any.sin_addr.s_addr = htonl(INADDR_ANY);
        any.sin_port = htons(port);
        memset(dst, 0, sizeof *dst);
        dst->sin_family = AF_INET;
        dst->sin_port = htons(port);
        if (inet_pton(AF_INET, group, &dst->sin_addr) != 1) {
            errno = EINVAL;
            return fail(b);
        }
        b->dest_len = sizeof *dst;
        memset(&mreq, 0, sizeof mreq);
        mreq.imr_multiaddr = dst->sin_addr;
        mreq.imr_interface.s_addr = htonl(INADDR_ANY);
        if (setsockopt(b->fd, IPPROTO_IP, IP_MULTICAST_TTL, &hop_limit, sizeof hop_limit) < 0 ||
            bind(b->fd, (struct sockaddr *)&any, sizeof any) < 0 ||
            setsockopt(b->fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof mreq) < 0) {
            return fail(b);
        }
    }
    open_sender(b, v6 ? AF_INET6 : AF_INET, hop_limit);
    return 0;
}

int bn_can_open(bn_bus_t *b, const char *ifname, bool fd)
{
    struct sockaddr_can addr;
    struct ifreq ifr;
    int zero = 0, one = 1;
    bus_reset(b, BN_BUS_CAN);
    if (strlen(ifname) >= IFNAMSIZ) {
        errno = ENAMETOOLONG;
        return fail(b);
    }
    b->fd = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
    if (b->fd < 0) {
        return fail(b);
    }
    memset(&ifr, 0, sizeof ifr);
    memcpy(ifr.ifr_name, ifname, strlen(ifname));
    if (ioctl(b->fd, SIOCGIFINDEX, &ifr) < 0) {
        return fail(b);
    }
    /* receive stamps of the kernel, as python-can's (best effort: else the drain time) */
    (void)setsockopt(b->fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof one);
    /* python-can's socketcan bus does not receive its own frames either */
    if (setsockopt(b->fd, SOL_CAN_RAW, CAN_RAW_RECV_OWN_MSGS, &zero, sizeof zero) < 0) {
        return fail(b);
    }
    if (fd) {
        if (setsockopt(b->fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &one, sizeof one) < 0) {
            return fail(b);
        }
        b->can_fd = true;
    }
    memset(&addr, 0, sizeof addr);
    addr.can_family = AF_CAN;
    addr.can_ifindex = ifr.ifr_ifindex;
    if (bind(b->fd, (struct sockaddr *)&addr, sizeof addr) < 0) {
        return fail(b);
    }
    return 0;
}

/* The bytes of one frame on the socket: (pointer, length) in *p, *n; 0 or -errno. */
static int encode(bn_bus_t *b, const bn_frame_t *f, struct canfd_frame *fr, const void **p,
                  size_t *n)
{
    if (b->kind == BN_BUS_UDP) {
        *n = bn_mp_pack(f, (double)bn_realtime_ns() * 1e-9, b->buf, sizeof b->buf);
        *p = b->buf;
        return *n ? 0 : -EMSGSIZE;
    }
    bool is_fd = (f->flags & BN_FD) != 0 || f->len > CAN_MAX_DLEN;
    if (f->len > (is_fd ? CANFD_MAX_DLEN : CAN_MAX_DLEN) || (is_fd && !b->can_fd)) {
        return -EMSGSIZE;
    }
    memset(fr, 0, sizeof *fr);
    fr->can_id = f->id | ((f->flags & BN_EXT) ? CAN_EFF_FLAG : 0) |
                 ((f->flags & BN_RTR) ? CAN_RTR_FLAG : 0);
    fr->len = f->len;
    if (is_fd) {
        fr->flags = (uint8_t)(((f->flags & BN_BRS) ? CANFD_BRS : 0) |
                              ((f->flags & BN_ESI) ? CANFD_ESI : 0));
    }
    memcpy(fr->data, f->data, f->len);
    *p = fr;
    *n = is_fd ? CANFD_MTU : CAN_MTU;
    return 0;
}

int bn_send(bn_bus_t *b, const bn_frame_t *f)
{
    struct canfd_frame fr;
    const void *p;
    size_t n;
    int r = encode(b, f, &fr, &p, &n);
    int64_t deadline = 0;
    int sfd = b->tx_fd >= 0 ? b->tx_fd : b->fd;
    while (r == 0) {
        ssize_t got = b->kind == BN_BUS_UDP && !b->tx_connected
                          ? sendto(sfd, p, n, 0, (struct sockaddr *)&b->dest, b->dest_len)
                          : write(sfd, p, n);
        if (got == (ssize_t)n) {
            b->tx++;
            return 0;
        }
        r = got < 0 ? -errno : -EIO;
        if (r != -EAGAIN && r != -EWOULDBLOCK && r != -ENOBUFS && r != -EINTR) {
            break;
        }
        int64_t now = bn_now_ns();
        if (deadline == 0) {
            deadline = now + b->send_wait_ns;
            b->tx_waits++;
        }
        if (now >= deadline) {
            break;
        }
        /* ENOBUFS (a full CAN queue) does not wake poll: look again within 50 us */
        int64_t wait = deadline - now < 50000 ? deadline - now : 50000;
        struct pollfd pf = {sfd, POLLOUT, 0};
        struct timespec ts = {0, (long)wait};
        (void)ppoll(&pf, 1, &ts, NULL);
        r = 0;
    }
    b->tx_errors++;
    return r;
}

int bn_send_many(bn_bus_t *b, const bn_frame_t *f, int n)
{
    if (b->kind != BN_BUS_UDP) {
        for (int j = 0; j < n; j++) {
            struct canfd_frame fr;
            const void *p;
            size_t len;
            if (encode(b, &f[j], &fr, &p, &len) != 0 || write(b->fd, p, len) != (ssize_t)len) {
                return j;
            }
            b->tx++;
        }
        return n;
    }
    if (n > BN_BATCH) {
        n = BN_BATCH;
    }
    b->tx_n = 0;
    double t = (double)bn_realtime_ns() * 1e-9; /* python-can stamps each at its send */
    for (int j = 0; j < n; j++) {
        size_t len = bn_mp_pack(&f[j], t, b->tx_buf[j], sizeof b->tx_buf[j]);
        if (len == 0) {
            n = j; /* the caller's bn_send counts it */
            break;
        }
        b->tx_iov[j].iov_len = len;
        /* a named address, even the connected one, makes the kernel look the route up */
        b->tx_msg[j].msg_hdr.msg_name = b->tx_connected ? NULL : &b->dest;
        b->tx_msg[j].msg_hdr.msg_namelen = b->tx_connected ? 0 : b->dest_len;
    }
    if (n == 0) {
        return 0;
    }
    int got = sendmmsg(b->tx_fd >= 0 ? b->tx_fd : b->fd, b->tx_msg, (unsigned)n, MSG_DONTWAIT);
    if (got < 0) {
        return 0;
    }
    b->tx_n = got;
    b->tx += (uint64_t)got;
    return got;
}

/* Refill the receive batch with one recvmmsg: the number taken, 0 (none), -errno. */
static int refill(bn_bus_t *b)
{
    b->rx_i = b->rx_n = 0;
    for (int j = 0; j < BN_BATCH; j++) b->rx_msg[j].msg_hdr.msg_controllen = sizeof b->rx_ctl[j];
    int n = recvmmsg(b->fd, b->rx_msg, BN_BATCH, MSG_DONTWAIT, NULL);
    if (n < 0) {
        return (errno == EAGAIN || errno == EWOULDBLOCK) ? 0 : -errno;
    }
    b->rx_n = n;
    b->rx_t_ns = bn_realtime_ns();
    return n;
}

/* A datagram of the last send batch, looped back (its bytes, time stamp included). */
static bool own(const bn_bus_t *b, const uint8_t *d, size_t n)
{
    for (int j = 0; j < b->tx_n; j++) {
        if (b->tx_iov[j].iov_len == n && memcmp(b->tx_buf[j], d, n) == 0) {
            return true;
        }
    }
    return false;
}

/* The kernel's receive stamp of a datagram (SO_TIMESTAMPNS), else the batch's drain time. */
static int64_t rx_stamp(const bn_bus_t *b, struct mmsghdr *m)
{
    struct msghdr *h = &m->msg_hdr;
    for (struct cmsghdr *c = CMSG_FIRSTHDR(h); c != NULL; c = CMSG_NXTHDR(h, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS) {
            struct timespec ts;
            memcpy(&ts, CMSG_DATA(c), sizeof ts);
            return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
        }
    }
    return b->rx_t_ns;
}

/* One datagram or frame without waiting: 1, 0 (none), -errno. */
static int recv_now(bn_bus_t *b, bn_frame_t *f)
{
    for (;;) {
        if (b->rx_i >= b->rx_n) {
            int r = refill(b);
            if (r <= 0) {
                return r;
            }
        }
        struct mmsghdr *m = &b->rx_msg[b->rx_i];
        const uint8_t *d = b->rx_buf[b->rx_i];
        size_t n = m->msg_len;
        int trunc = (m->msg_hdr.msg_flags & MSG_TRUNC) != 0;
        int64_t stamp = rx_stamp(b, m);
        b->rx_i++;
        if (b->kind == BN_BUS_UDP) {
            if (own(b, d, n)) {
                b->rx_own++;
                continue;
            }
            if (trunc || bn_mp_unpack(d, n, f) != 0) {
                b->rx_malformed++;
                continue;
            }
        } else {
            struct canfd_frame fr;
            if (trunc || (n != CAN_MTU && n != CANFD_MTU)) {
                b->rx_malformed++;
                continue;
            }
            memcpy(&fr, d, n);
            memset(f, 0, sizeof *f);
            if (fr.can_id & CAN_EFF_FLAG) {
                f->flags |= BN_EXT;
                f->id = fr.can_id & CAN_EFF_MASK;
            } else {
                f->id = fr.can_id & CAN_SFF_MASK;
            }
            f->flags |= (fr.can_id & CAN_RTR_FLAG) ? BN_RTR : 0;
            f->flags |= (fr.can_id & CAN_ERR_FLAG) ? BN_ERR : 0;
            if (n == CANFD_MTU) {
                f->flags |= BN_FD;
                f->flags |= (fr.flags & CANFD_BRS) ? BN_BRS : 0;
                f->flags |= (fr.flags & CANFD_ESI) ? BN_ESI : 0;
            }
            f->len = fr.len > CANFD_MAX_DLEN ? CANFD_MAX_DLEN : fr.len;
            memcpy(f->data, fr.data, f->len);
        }
        f->t_ns = stamp;
        b->rx++;
        return 1;
    }
}

int bn_recv_until(bn_bus_t *b, bn_frame_t *f, int64_t deadline_ns)
{
    for (;;) {
        int r = recv_now(b, f);
        if (r != 0) {
            return r;
        }
        int64_t left = deadline_ns - bn_now_ns();
        if (deadline_ns == 0 || left <= 0) {
            return 0;
        }
        struct pollfd p = {b->fd, POLLIN, 0};
        struct timespec ts = {(time_t)(left / 1000000000), (long)(left % 1000000000)};
        if (ppoll(&p, 1, &ts, NULL) < 0) {
            return errno == EINTR ? 0 : -errno; /* a signal: the caller checks its flags */
        }
    }
}

int bn_recv(bn_bus_t *b, bn_frame_t *f, int64_t timeout_ns)
{
    return bn_recv_until(b, f, timeout_ns > 0 ? bn_now_ns() + timeout_ns : 0);
}

void bn_close(bn_bus_t *b)
{
    if (b->fd >= 0) {
        close(b->fd);
    }
    if (b->tx_fd >= 0) {
        close(b->tx_fd);
    }
    b->fd = b->tx_fd = -1;
    b->tx_connected = false;
}

int bn_held_put(bn_held_t *h, const bn_frame_t *f, bn_frame_t *out)
{
    int full = h->n == BN_HELD;
    if (full) {
        bn_held_take(h, out);
        h->full++;
    }
    h->f[(h->head + h->n) % BN_HELD] = *f;
    h->n++;
    h->total++;
    if ((uint64_t)h->n > h->max) h->max = (uint64_t)h->n;
    return full;
}

void bn_held_take(bn_held_t *h, bn_frame_t *out)
{
    *out = h->f[h->head];
    h->head = (h->head + 1) % BN_HELD;
    h->n--;
}
