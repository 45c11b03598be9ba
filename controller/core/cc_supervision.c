/* Drive supervision (cc_supervision.h); the thresholds' derivations are in
 * controller/_supervision.py, SupervisionPars.design. */
#include "cc_supervision.h"

#include "cc_math.h"

void cc_sup_reset_windows(cc_sup_t *s)
{
    for (int j = 0; j < 2; j++) {
        s->n_rail[j] = 0;
        s->stuck_lo[j] = INFINITY;
        s->stuck_hi[j] = -INFINITY;
        s->du_lo[j] = INFINITY;
        s->du_hi[j] = -INFINITY;
    }
    s->stuck_n = 0;
    s->blk_n = 0;
    s->blk_len = s->n_open_min;
    s->blk_scored = 0;
    for (int j = 0; j < 3; j++)
        s->ms[j] = s->s[j] = 0.0;
    s->u_sum = 0.0;
    s->u_n = 0;
}

void cc_sup_init(cc_sup_t *s, double T_s, double i_rail, long long n_range, double i_res,
                 double du_stuck, long long n_stuck, double i_min, double rho_open,
                 long long n_open_min, long long n_open_max, double u_uv, double u_ov,
                 double u_hyst, long long n_dc)
{
    s->T_s = T_s;
    s->i_rail = i_rail;
    s->n_range = n_range;
    s->i_res = i_res;
    s->du_stuck = du_stuck;
    s->n_stuck = n_stuck;
    s->i_min = i_min;
    s->rho_open = rho_open;
    s->n_open_min = n_open_min;
    s->n_open_max = n_open_max;
    s->u_uv = u_uv;
    s->u_ov = u_ov;
    s->u_hyst = u_hyst;
    s->n_dc = n_dc;
    s->latched = 0;
    s->detected_k = -1;
    cc_sup_reset_windows(s);
}

long long cc_sup_check(cc_sup_t *s, double i_a, double i_b, double u_dc, const cc_out_t *o)
{
    s->u_sum += u_dc;
    s->u_n += 1;
    if (s->u_n >= s->n_dc) {
        double u = s->u_sum / (double)s->u_n;
        s->u_sum = 0.0;
        s->u_n = 0;
        if (u < s->u_uv)
            return CC_MODE_DC_UNDERVOLTAGE;
        if (u > s->u_ov)
            return CC_MODE_DC_OVERVOLTAGE;
    }
    if (!(o->enable && o->mode == CC_MODE_RUN)) {
        s->n_rail[0] = s->n_rail[1] = 0;
        s->stuck_n = 0;
        s->blk_n = 0;
        for (int j = 0; j < 3; j++)
            s->ms[j] = s->s[j] = 0.0;
        return 0;
    }
    /* out of range */
    double i2[2] = {i_a, i_b};
    for (int j = 0; j < 2; j++) {
        s->n_rail[j] = fabs(i2[j]) >= s->i_rail ? s->n_rail[j] + 1 : 0;
        if (s->n_rail[j] >= s->n_range)
            return CC_MODE_CURRENT_SENSOR;
    }
    /* stuck: reading range against the commanded phase voltage's range */
    double mean = (o->d_a + o->d_b + o->d_c) / 3.0;
    double d2[2] = {o->d_a, o->d_b};
    for (int j = 0; j < 2; j++) {
        double u = (d2[j] - mean) * u_dc;
        s->stuck_lo[j] = fmin(s->stuck_lo[j], i2[j]);
        s->stuck_hi[j] = fmax(s->stuck_hi[j], i2[j]);
        s->du_lo[j] = fmin(s->du_lo[j], u);
        s->du_hi[j] = fmax(s->du_hi[j], u);
    }
    s->stuck_n += 1;
    if (s->stuck_n >= s->n_stuck) {
        int hit = 0, mode = 0;
        for (int j = 0; j < 2 && !hit; j++) {
            hit = s->stuck_hi[j] - s->stuck_lo[j] <= s->i_res
                  && s->du_hi[j] - s->du_lo[j] >= s->du_stuck
                  && s->stuck_hi[1 - j] - s->stuck_lo[1 - j] > s->i_res;
            /* held within a resolution step of zero: the phase carries nothing (an open
             * phase, or a sensor reading zero); held elsewhere: a stuck sensor */
            if (hit)
                mode = fabs(0.5 * (s->stuck_hi[j] + s->stuck_lo[j])) <= s->i_res
                           ? CC_MODE_OPEN_PHASE
                           : CC_MODE_CURRENT_SENSOR;
        }
        s->stuck_n = 0;
        for (int j = 0; j < 2; j++) {
            s->stuck_lo[j] = INFINITY;
            s->stuck_hi[j] = -INFINITY;
            s->du_lo[j] = INFINITY;
            s->du_hi[j] = -INFINITY;
        }
        if (hit)
            return mode;
    }
    /* open phase: mean squares about the block's mean over one electrical period of the
     * estimated speed */
    if (s->blk_n == 0) {
        double w = fabs(o->w_hat) * s->T_s; /* electrical angle per period */
        /* below one electrical period per n_open_max the block is not scored (0) */
        long long n = w * (double)s->n_open_max < CC_TWO_PI
                        ? 0
                        : (long long)nearbyint(CC_TWO_PI / w);
        s->blk_len = n > s->n_open_min ? n : s->n_open_min;
        s->blk_scored = n > 0;
    }
    double i_c = -i_a - i_b;
    s->ms[0] += i_a * i_a;
    s->ms[1] += i_b * i_b;
    s->ms[2] += i_c * i_c;
    s->s[0] += i_a;
    s->s[1] += i_b;
    s->s[2] += i_c;
    s->blk_n += 1;
    if (s->blk_n >= s->blk_len) {
        long long n = s->blk_n;
        double ac[3];
        for (int j = 0; j < 3; j++) {
            ac[j] = s->ms[j] - s->s[j] * s->s[j] / (double)n;
            s->ms[j] = s->s[j] = 0.0;
        }
        s->blk_n = 0;
        if (!s->blk_scored)
            return 0;
        double floor2 = s->i_min * s->i_min * (double)n;
        double r2 = s->rho_open * s->rho_open;
        for (int j = 0; j < 3; j++) {
            double others = 0.5 * (ac[(j + 1) % 3] + ac[(j + 2) % 3]);
            if (others >= floor2 && ac[j] <= r2 * others)
                return CC_MODE_OPEN_PHASE;
        }
    }
    return 0;
}

int cc_sup_release_ok(const cc_sup_t *s, double u_dc)
{
    if (s->latched == CC_MODE_DC_UNDERVOLTAGE)
        return u_dc >= s->u_uv + s->u_hyst;
    if (s->latched == CC_MODE_DC_OVERVOLTAGE)
        return u_dc <= s->u_ov - s->u_hyst;
    return 0;
}

static void stopped(const cc_sup_t *s, cc_out_t *o)
{
    o->d_a = o->d_b = o->d_c = 0.5;
    o->enable = 0;
    o->mode = s->latched;
}

void cc_sup_after(cc_sup_t *s, cc_foc_t *c, const cc_meas_t *m, cc_out_t *o)
{
    if (s->latched) {
        if (o->mode != CC_MODE_DISABLED && cc_sup_release_ok(s, m->u_dc)) {
            s->latched = 0; /* enabled again, the condition gone */
            cc_sup_reset_windows(s);
        } else {
            if (o->mode != CC_MODE_DISABLED)
                cc_foc_set_enable(c, 0);
            stopped(s, o);
            return;
        }
    }
    long long hit = cc_sup_check(s, m->i_a, m->i_b, m->u_dc, o);
    if (!hit)
        return;
    s->latched = hit;
    s->detected_k = m->k;
    cc_foc_set_enable(c, 0);
    stopped(s, o);
}
