/* Copies of a bench command, dropped before they reach Python (bn.h). */
#include <string.h>

#include "bn.h"

void bn_cmd_seen_init(bn_cmd_seen_t *s, uint32_t id, int64_t span)
{
    memset(s, 0, sizeof *s);
    s->id = id;
    s->span = span;
}

int bn_cmd_seen_copy(bn_cmd_seen_t *s, const bn_frame_t *f, int64_t now)
{
    if (s->id == 0 || f->id != s->id || (f->flags & BN_EXT) || f->len > 8) return 0;
    for (int j = 0; j < s->n; j++) {
        int64_t age = now - s->k[j];
        if (age >= 0 && age <= s->span && s->len[j] == f->len && s->flags[j] == f->flags &&
            memcmp(s->data[j], f->data, f->len) == 0) {
            s->copies++;
            return 1;
        }
    }
    return 0;
}

void bn_cmd_seen_take(bn_cmd_seen_t *s, const bn_frame_t *f, int64_t now)
{
    if (s->id == 0 || f->id != s->id || (f->flags & BN_EXT) || f->len > 8) return;
    int j = s->head;
    s->len[j] = f->len;
    s->flags[j] = f->flags;
    memset(s->data[j], 0, sizeof s->data[j]);
    memcpy(s->data[j], f->data, f->len);
    s->k[j] = now;
    s->head = (j + 1) % BN_CMD_SEEN;
    if (s->n < BN_CMD_SEEN) s->n++;
}
