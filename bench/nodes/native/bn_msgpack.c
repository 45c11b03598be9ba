/* python-can's udp_multicast datagram: a msgpack map (no allocation).
 *
 * python-can (can/interfaces/udp_multicast/utils.py) packs
 *   msgpack.packb({"timestamp": float, "arbitration_id": int,
 *                  "is_extended_id": bool, "is_remote_frame": bool,
 *                  "is_error_frame": bool, "channel": None | str, "dlc": int,
 *                  "data": bytes, "is_fd": bool, "bitrate_switch": bool,
 *                  "error_state_indicator": bool}, use_bin_type=True)
 * and its receiver builds can.Message(**map, check=True) with the receive
 * time as timestamp.  The writer below emits the same keys in the same order
 * (channel nil); the reader takes the msgpack types those values can have
 * (nil, bool, ints, float32/64, str, bin) and skips keys it does not know.
 */
#include <string.h>

#include "bn.h"

/* ---- writer ---- */

typedef struct {
    uint8_t *p;
    size_t n, cap;
    bool overflow;
} wbuf_t;

static void put(wbuf_t *w, const void *src, size_t len)
{
    if (w->overflow || w->n + len > w->cap) {
        w->overflow = true;
        return;
    }
    memcpy(w->p + w->n, src, len);
    w->n += len;
}

static void put_u8(wbuf_t *w, uint8_t v)
{
    put(w, &v, 1);
}

static void put_be(wbuf_t *w, uint64_t v, int bytes)
{
    uint8_t b[8];
    for (int i = 0; i < bytes; i++) {
        b[i] = (uint8_t)(v >> (8 * (bytes - 1 - i)));
    }
    put(w, b, (size_t)bytes);
}

static void put_key(wbuf_t *w, const char *s)
{
    size_t len = strlen(s); /* every key is shorter than 32: fixstr */
    put_u8(w, (uint8_t)(0xa0u | len));
    put(w, s, len);
}

static void put_bool(wbuf_t *w, bool v)
{
    put_u8(w, v ? 0xc3u : 0xc2u);
}

static void put_uint(wbuf_t *w, uint64_t v)
{
    if (v < 0x80u) {
        put_u8(w, (uint8_t)v);
    } else if (v <= 0xffu) {
        put_u8(w, 0xccu);
        put_be(w, v, 1);
    } else if (v <= 0xffffu) {
        put_u8(w, 0xcdu);
        put_be(w, v, 2);
    } else if (v <= 0xffffffffu) {
        put_u8(w, 0xceu);
        put_be(w, v, 4);
    } else {
        put_u8(w, 0xcfu);
        put_be(w, v, 8);
    }
}

static void put_f64(wbuf_t *w, double v)
{
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    put_u8(w, 0xcbu);
    put_be(w, bits, 8);
}

size_t bn_mp_pack(const bn_frame_t *f, double timestamp_s, uint8_t *out, size_t cap)
{
    wbuf_t w = {out, 0, cap, false};
    size_t len = f->len > BN_MAX_DATA ? BN_MAX_DATA : f->len;
    put_u8(&w, 0x80u | 11u); /* fixmap of 11 */
    put_key(&w, "timestamp");
    put_f64(&w, timestamp_s);
    put_key(&w, "arbitration_id");
    put_uint(&w, f->id);
    put_key(&w, "is_extended_id");
    put_bool(&w, (f->flags & BN_EXT) != 0);
    put_key(&w, "is_remote_frame");
    put_bool(&w, (f->flags & BN_RTR) != 0);
    put_key(&w, "is_error_frame");
    put_bool(&w, (f->flags & BN_ERR) != 0);
    put_key(&w, "channel");
    put_u8(&w, 0xc0u); /* None */
    put_key(&w, "dlc");
    put_uint(&w, len);
    put_key(&w, "data");
    put_u8(&w, 0xc4u); /* bin 8 */
    put_u8(&w, (uint8_t)len);
    put(&w, f->data, len);
    put_key(&w, "is_fd");
    put_bool(&w, (f->flags & BN_FD) != 0);
    put_key(&w, "bitrate_switch");
    put_bool(&w, (f->flags & BN_BRS) != 0);
    put_key(&w, "error_state_indicator");
    put_bool(&w, (f->flags & BN_ESI) != 0);
    return w.overflow ? 0 : w.n;
}

/* ---- reader ---- */

typedef struct {
    const uint8_t *p;
    size_t n, i;
} rbuf_t;

/* A scalar value as the reader keeps it. */
typedef struct {
    enum { V_NIL, V_BOOL, V_INT, V_FLOAT, V_STR, V_BIN } kind;
    uint64_t u;         /* bool, int (two's complement for negatives) */
    double d;           /* float */
    const uint8_t *ptr; /* str, bin */
    size_t len;
} value_t;

static bool take(rbuf_t *r, size_t len, const uint8_t **out)
{
    if (len > r->n - r->i) {
        return false;
    }
    *out = r->p + r->i;
    r->i += len;
    return true;
}

static bool take_be(rbuf_t *r, int bytes, uint64_t *v)
{
    const uint8_t *b;
    if (!take(r, (size_t)bytes, &b)) {
        return false;
    }
    *v = 0;
    for (int i = 0; i < bytes; i++) {
        *v = (*v << 8) | b[i];
    }
    return true;
}

static bool read_value(rbuf_t *r, value_t *v)
{
    const uint8_t *t;
    uint64_t x;
    if (!take(r, 1, &t)) {
        return false;
    }
    uint8_t c = *t;
    v->kind = V_INT;
    if (c <= 0x7fu) {
        v->u = c;
        return true;
    }
    if (c >= 0xe0u) { /* negative fixint */
        v->u = (uint64_t)(int64_t)(int8_t)c;
        return true;
    }
    if ((c & 0xe0u) == 0xa0u || c == 0xd9u || c == 0xdau || c == 0xc4u || c == 0xc5u) {
        size_t len;
        if ((c & 0xe0u) == 0xa0u) {
            len = c & 0x1fu;
        } else if (!take_be(r, (c == 0xd9u || c == 0xc4u) ? 1 : 2, &x)) {
            return false;
        } else {
            len = (size_t)x;
        }
        v->kind = (c == 0xc4u || c == 0xc5u) ? V_BIN : V_STR;
        v->len = len;
        return take(r, len, &v->ptr);
    }
    switch (c) {
    case 0xc0u:
        v->kind = V_NIL;
        return true;
    case 0xc2u:
    case 0xc3u:
        v->kind = V_BOOL;
        v->u = c == 0xc3u;
        return true;
    case 0xccu:
    case 0xcdu:
    case 0xceu:
    case 0xcfu:
        return take_be(r, 1 << (c - 0xccu), &v->u);
    case 0xd0u:
    case 0xd1u:
    case 0xd2u:
    case 0xd3u: {
        int bytes = 1 << (c - 0xd0u);
        if (!take_be(r, bytes, &x)) {
            return false;
        }
        if (bytes < 8 && (x >> (8 * bytes - 1)) & 1u) {
            x |= ~(uint64_t)0 << (8 * bytes); /* sign-extend */
        }
        v->u = x;
        return true;
    }
    case 0xcau: {
        float fl;
        uint32_t bits;
        if (!take_be(r, 4, &x)) {
            return false;
        }
        bits = (uint32_t)x;
        memcpy(&fl, &bits, sizeof fl);
        v->kind = V_FLOAT;
        v->d = fl;
        return true;
    }
    case 0xcbu:
        if (!take_be(r, 8, &x)) {
            return false;
        }
        v->kind = V_FLOAT;
        memcpy(&v->d, &x, sizeof v->d);
        return true;
    default:
        return false; /* arrays, maps, ext: never in python-can's message */
    }
}

static bool key_is(const value_t *k, const char *s)
{
    size_t len = strlen(s);
    return k->kind == V_STR && k->len == len && memcmp(k->ptr, s, len) == 0;
}

static bool truthy(const value_t *v)
{
    return (v->kind == V_BOOL || v->kind == V_INT) && v->u != 0;
}

int bn_mp_unpack(const uint8_t *in, size_t n, bn_frame_t *f)
{
    rbuf_t r = {in, n, 0};
    const uint8_t *t;
    uint64_t count;
    memset(f, 0, sizeof *f);
    if (!take(&r, 1, &t)) {
        return -1;
    }
    if ((*t & 0xf0u) == 0x80u) {
        count = *t & 0x0fu;
    } else if (*t == 0xdeu) {
        if (!take_be(&r, 2, &count)) {
            return -1;
        }
    } else {
        return -1;
    }
    for (uint64_t i = 0; i < count; i++) {
        value_t k, v;
        if (!read_value(&r, &k) || !read_value(&r, &v)) {
            return -1;
        }
        if (key_is(&k, "arbitration_id")) {
            if (v.kind != V_INT || v.u > 0x1fffffffu) {
                return -1;
            }
            f->id = (uint32_t)v.u;
        } else if (key_is(&k, "data")) {
            if (v.kind == V_NIL) {
                continue;
            }
            if ((v.kind != V_BIN && v.kind != V_STR) || v.len > BN_MAX_DATA) {
                return -1;
            }
            f->len = (uint8_t)v.len;
            memcpy(f->data, v.ptr, v.len);
        } else if (key_is(&k, "is_extended_id")) {
            f->flags |= truthy(&v) ? BN_EXT : 0;
        } else if (key_is(&k, "is_remote_frame")) {
            f->flags |= truthy(&v) ? BN_RTR : 0;
        } else if (key_is(&k, "is_error_frame")) {
            f->flags |= truthy(&v) ? BN_ERR : 0;
        } else if (key_is(&k, "is_fd")) {
            f->flags |= truthy(&v) ? BN_FD : 0;
        } else if (key_is(&k, "bitrate_switch")) {
            f->flags |= truthy(&v) ? BN_BRS : 0;
        } else if (key_is(&k, "error_state_indicator")) {
            f->flags |= truthy(&v) ? BN_ESI : 0;
        }
        /* timestamp: the receiver's own clock counts (as python-can's);
         * channel, dlc (len(data) for data frames) and unknown keys: skipped */
    }
    return r.i == r.n ? 0 : -1;
}
