/* The compiled engine of controller.Controller: the per-period step in C.
 *
 * A second implementation of Controller.step (controller/_controller.py) in
 * the speed-control and alignment modes, with every shipped estimator: tt-dq,
 * tt-ab and sfhf (rotating injection, model normalisation), square-wave and
 * square-wave-nocic (Xue), sensored, and the hybrids hybrid-tt-dq and
 * hybrid-square-wave.  Each Python block is one C struct
 * and one function of the same name, operation for operation in the same
 * order, so that the two engines give the same trace bit for bit
 * (tests/test_controller_engine.py runs every shipped scenario on both):
 *
 *   PIController.output/update   pi_output, pi_update       (_pi.py)
 *   FirstOrder/FirstOrder2       fo_update, fo2_update      (_filters.py)
 *   Biquad2                      bq2_update                 (_filters.py)
 *   PositionObserver.update      pll_update                 (_pll.py)
 *   LuenbergerObserver.step      luen_step                  (_luenberger.py)
 *   CicFilter/CicInterpolator    cic_step, cici_step, cici_prime (_cic.py)
 *   svpwm                        svpwm                      (_svpwm.py)
 *   RotatingHFEstimator._publish rot_publish                (_rotating.py)
 *   TTDQEstimator.update         ttdq_update                (_tt_dq.py)
 *   TTABEstimator.update         ttab_update                (_tt_ab.py)
 *   SFHFEstimator.update         sfhf_update                (_sfhf.py)
 *   SquareWaveEstimator.update   sqw_update                 (_square_wave.py)
 *   SensoredEstimator.update     sens_update                (_sensored.py)
 *   FluxObserver._k1T/_predict/_flux_error/update/update_slaved
 *                                flux_k1T, flux_predict, flux_error, flux_update,
 *                                flux_update_slaved         (_flux_observer.py)
 *   TransitionBand.play/weights  band_play, band_weights    (_hybrid.py)
 *   _PllTracker, _LuenbergerTracker (w_smooth, sync)
 *                                tracker_w_smooth, tracker_sync (_hybrid.py)
 *   HybridEstimator.update/injection hyb_update, est_injection (_hybrid.py)
 *   Controller.step              core_step                  (_controller.py)
 *
 * Keep them in step: a change of an equation in one of those files is a
 * change here.  Built with -ffp-contract=off (no fused multiply-add).
 *
 * The Python objects stay the description of the controller: load() reads
 * every constant and state from them (each block's load_* function reads the
 * attributes of its Python class), store() writes the states back.  What
 * stays in Python (step() returns None before it changes anything, and the
 * Controller runs that period in Python on the stored states): the disabled
 * and polarity modes' transitions, the polarity test, the periods in which
 * the alignment hands over to the polarity test or the speed loop, and the
 * CIC's periodic re-anchoring of its integrator (every 4096 periods).
 *
 * Purity: the core reads a measurement's theta_e and w_e only for the
 * sensored estimator, as the Python controller does.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <math.h>

#define MODE_DISABLED 0
#define MODE_ALIGN 1
#define MODE_POLARITY 2
#define MODE_RUN 3

#define KIND_TTDQ 1
#define KIND_TTAB 2
#define KIND_SFHF 3
#define KIND_SQW 4
#define KIND_SENSORED 5
#define KIND_HYB_TTDQ 6
#define KIND_HYB_SQW 7

#define CIC_MAX 64
#define CIC_REANCHOR 4096

static double TWO_PI, SQRT3_INV, SQRT3_HALF;

/* ------------------------------------------------------------ helpers */
static double py_mod(double x, double m)
{
    /* Python's float %: the result takes the sign of the divisor */
    double mod = fmod(x, m);
    if (mod != 0.0) {
        if ((m < 0.0) != (mod < 0.0))
            mod += m;
    } else {
        mod = copysign(0.0, m);
    }
    return mod;
}

static int get_d(PyObject *o, const char *name, double *out)
{
    PyObject *v = PyObject_GetAttrString(o, name);
    if (v == NULL)
        return -1;
    *out = PyFloat_AsDouble(v);
    Py_DECREF(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static int get_ll(PyObject *o, const char *name, long long *out)
{
    PyObject *v = PyObject_GetAttrString(o, name);
    if (v == NULL)
        return -1;
    *out = PyLong_AsLongLong(v);
    Py_DECREF(v);
    return (*out == -1 && PyErr_Occurred()) ? -1 : 0;
}

static int get_bool(PyObject *o, const char *name, int *out)
{
    PyObject *v = PyObject_GetAttrString(o, name);
    if (v == NULL)
        return -1;
    *out = PyObject_IsTrue(v);
    Py_DECREF(v);
    return *out < 0 ? -1 : 0;
}

static int set_obj(PyObject *o, const char *name, PyObject *v)
{
    if (v == NULL)
        return -1;
    int r = PyObject_SetAttrString(o, name, v);
    Py_DECREF(v);
    return r;
}

static int set_d(PyObject *o, const char *name, double v)
{
    return set_obj(o, name, PyFloat_FromDouble(v));
}

static int set_ll(PyObject *o, const char *name, long long v)
{
    return set_obj(o, name, PyLong_FromLongLong(v));
}

static PyObject *sub(PyObject *o, const char *name) /* new reference */
{
    return PyObject_GetAttrString(o, name);
}

#define TRY(x) do { if ((x) < 0) return -1; } while (0)

/* ------------------------------------------------- PIController (_pi.py) */
typedef struct { double k_p, k_i, k_t, T_s, u_i, e, u; } PI;

static double pi_output(PI *p, double r, double y, double u_ff)
{
    p->e = r - y;
    p->u = p->k_t * r - p->k_p * y + p->u_i + u_ff;
    return p->u;
}

static void pi_update(PI *p, double u_lim)
{
    p->u_i += p->T_s * p->k_i * (p->e + (u_lim - p->u) / p->k_t);
}

static int load_pi(PI *p, PyObject *o)
{
    TRY(get_d(o, "k_p", &p->k_p)); TRY(get_d(o, "k_i", &p->k_i));
    TRY(get_d(o, "k_t", &p->k_t)); TRY(get_d(o, "T_s", &p->T_s));
    TRY(get_d(o, "u_i", &p->u_i)); TRY(get_d(o, "_e", &p->e));
    TRY(get_d(o, "_u", &p->u));
    return 0;
}

static int store_pi(const PI *p, PyObject *o)
{
    TRY(set_d(o, "u_i", p->u_i)); TRY(set_d(o, "_e", p->e)); TRY(set_d(o, "_u", p->u));
    return 0;
}

/* ------------------------------------- FirstOrder, FirstOrder2 (_filters.py) */
typedef struct { double b0, b1, a1, s; } FO;
typedef struct { double b0, b1, a1, s1, s2; } FO2;

static double fo_update(FO *f, double x)
{
    double y = f->b0 * x + f->s;
    f->s = f->b1 * x - f->a1 * y;
    return y;
}

static void fo2_update(FO2 *f, double x_1, double x_2, double *y1, double *y2)
{
    double y_1 = f->b0 * x_1 + f->s1;
    double y_2 = f->b0 * x_2 + f->s2;
    f->s1 = f->b1 * x_1 - f->a1 * y_1;
    f->s2 = f->b1 * x_2 - f->a1 * y_2;
    *y1 = y_1;
    *y2 = y_2;
}

static int load_fo(FO *f, PyObject *o)
{
    TRY(get_d(o, "b0", &f->b0)); TRY(get_d(o, "b1", &f->b1)); TRY(get_d(o, "a1", &f->a1));
    TRY(get_d(o, "_s", &f->s));
    return 0;
}

static int store_fo(const FO *f, PyObject *o) { return set_d(o, "_s", f->s); }

static int load_fo2(FO2 *f, PyObject *o)
{
    TRY(get_d(o, "b0", &f->b0)); TRY(get_d(o, "b1", &f->b1)); TRY(get_d(o, "a1", &f->a1));
    TRY(get_d(o, "_s1", &f->s1)); TRY(get_d(o, "_s2", &f->s2));
    return 0;
}

static int store_fo2(const FO2 *f, PyObject *o)
{
    TRY(set_d(o, "_s1", f->s1)); TRY(set_d(o, "_s2", f->s2));
    return 0;
}

/* --------------------------------------------------- Biquad2 (_filters.py) */
typedef struct { double b0, b1, b2, a1, a2, p1, p2, q1, q2; } BQ2;

static void bq2_update(BQ2 *f, double x_1, double x_2, double *y1, double *y2)
{
    double y_1 = f->b0 * x_1 + f->p1;
    double y_2 = f->b0 * x_2 + f->q1;
    f->p1 = f->b1 * x_1 - f->a1 * y_1 + f->p2;
    f->q1 = f->b1 * x_2 - f->a1 * y_2 + f->q2;
    f->p2 = f->b2 * x_1 - f->a2 * y_1;
    f->q2 = f->b2 * x_2 - f->a2 * y_2;
    *y1 = y_1;
    *y2 = y_2;
}

static int load_bq2(BQ2 *f, PyObject *o)
{
    TRY(get_d(o, "b0", &f->b0)); TRY(get_d(o, "b1", &f->b1)); TRY(get_d(o, "b2", &f->b2));
    TRY(get_d(o, "a1", &f->a1)); TRY(get_d(o, "a2", &f->a2));
    TRY(get_d(o, "_p1", &f->p1)); TRY(get_d(o, "_p2", &f->p2));
    TRY(get_d(o, "_q1", &f->q1)); TRY(get_d(o, "_q2", &f->q2));
    return 0;
}

static int store_bq2(const BQ2 *f, PyObject *o)
{
    TRY(set_d(o, "_p1", f->p1)); TRY(set_d(o, "_p2", f->p2));
    TRY(set_d(o, "_q1", f->q1)); TRY(set_d(o, "_q2", f->q2));
    return 0;
}

/* a retuned BPF (tt-dq's bpf_tracking): its coefficients as well */
static int store_bq2_tuned(const BQ2 *f, PyObject *o)
{
    TRY(store_bq2(f, o));
    TRY(set_d(o, "b0", f->b0)); TRY(set_d(o, "b2", f->b2));
    TRY(set_d(o, "a1", f->a1)); TRY(set_d(o, "a2", f->a2));
    return 0;
}

/* ------------------------------------------ PositionObserver (_pll.py) */
typedef struct { double k_p, k_i, T_s, theta_hat, w_hat, w_i; } PLL;

static void pll_update(PLL *p, double err)
{
    p->w_i += p->T_s * p->k_i * err;
    p->w_hat = p->k_p * err + p->w_i;
    p->theta_hat = py_mod(p->theta_hat + p->T_s * p->w_hat, TWO_PI);
}

static int load_pll(PLL *p, PyObject *o)
{
    TRY(get_d(o, "k_p", &p->k_p)); TRY(get_d(o, "k_i", &p->k_i)); TRY(get_d(o, "T_s", &p->T_s));
    TRY(get_d(o, "theta_hat", &p->theta_hat)); TRY(get_d(o, "w_hat", &p->w_hat));
    TRY(get_d(o, "w_i", &p->w_i));
    return 0;
}

static int store_pll(const PLL *p, PyObject *o)
{
    TRY(set_d(o, "theta_hat", p->theta_hat)); TRY(set_d(o, "w_hat", p->w_hat));
    TRY(set_d(o, "w_i", p->w_i));
    return 0;
}

/* ------------------------------------ LuenbergerObserver (_luenberger.py) */
typedef struct { double T_s, g1, g2, g3, gt, theta_hat, w_hat, x; } LUEN;

static void luen_step(LUEN *o, double e, double tau_e)
{
    double w = o->w_hat;
    double th = o->theta_hat + o->T_s * w + o->g3 * e;
    if (th >= TWO_PI) {
        th -= TWO_PI;
        if (th >= TWO_PI)
            th = py_mod(th, TWO_PI);
    } else if (th < 0.0) {
        th += TWO_PI;
        if (th < 0.0)
            th = py_mod(th, TWO_PI);
    }
    o->theta_hat = th;
    o->w_hat = w + o->T_s * o->x + o->g2 * e + o->gt * tau_e;
    o->x += o->g1 * e;
}

static int load_luen(LUEN *l, PyObject *o)
{
    TRY(get_d(o, "T_s", &l->T_s)); TRY(get_d(o, "_g1", &l->g1)); TRY(get_d(o, "_g2", &l->g2));
    TRY(get_d(o, "_g3", &l->g3)); TRY(get_d(o, "_gt", &l->gt));
    TRY(get_d(o, "theta_hat", &l->theta_hat)); TRY(get_d(o, "w_hat", &l->w_hat));
    TRY(get_d(o, "x", &l->x));
    return 0;
}

static int store_luen(const LUEN *l, PyObject *o)
{
    TRY(set_d(o, "theta_hat", l->theta_hat)); TRY(set_d(o, "w_hat", l->w_hat));
    TRY(set_d(o, "x", l->x));
    return 0;
}

/* ------------------------------------ CicFilter, CicInterpolator (_cic.py) */
typedef struct { long long M; double inv_M; double buf[CIC_MAX]; long long i; double acc; long long n; } CIC;
typedef struct { CIC cic; double held; } CICI;

static double cic_step(CIC *c, double x)
{
    /* the re-anchoring every CIC_REANCHOR steps (Python's sum of the delay
     * line) is left to Python: core_step hands such a period over */
    long long i = c->i;
    c->acc += x - c->buf[i];
    c->buf[i] = x;
    i += 1;
    c->i = i == c->M ? 0 : i;
    c->n += 1;
    return c->acc * c->inv_M;
}

static void cic_reset(CIC *c)
{
    for (long long j = 0; j < c->M; j++)
        c->buf[j] = 0.0;
    c->i = 0;
    c->acc = 0.0;
    c->n = 0;
}

static void cici_prime(CICI *f, double x0)
{
    cic_reset(&f->cic);
    f->held = x0;
    for (long long j = 0; j < f->cic.M; j++)
        cic_step(&f->cic, x0);
}

static double cici_step(CICI *f, int fresh, double x)
{
    if (fresh)
        f->held = x;
    return cic_step(&f->cic, f->held);
}

static int load_cici(CICI *f, PyObject *o)
{
    PyObject *c = sub(o, "_cic");
    if (c == NULL)
        return -1;
    int r = -1;
    PyObject *buf = NULL;
    CIC *k = &f->cic;
    if (get_d(o, "_held", &f->held) < 0 || get_ll(c, "M", &k->M) < 0
        || get_d(c, "_inv_M", &k->inv_M) < 0 || get_ll(c, "_i", &k->i) < 0
        || get_d(c, "_acc", &k->acc) < 0 || get_ll(c, "_n", &k->n) < 0)
        goto done;
    if (k->M < 1 || k->M > CIC_MAX) {
        PyErr_Format(PyExc_ValueError, "compiled controller: CIC order %lld outside 1..%d",
                     k->M, CIC_MAX);
        goto done;
    }
    buf = sub(c, "_buf");
    if (buf == NULL)
        goto done;
    for (long long j = 0; j < k->M; j++) {
        PyObject *v = PySequence_GetItem(buf, (Py_ssize_t)j);
        if (v == NULL)
            goto done;
        k->buf[j] = PyFloat_AsDouble(v);
        Py_DECREF(v);
        if (PyErr_Occurred())
            goto done;
    }
    r = 0;
done:
    Py_XDECREF(buf);
    Py_DECREF(c);
    return r;
}

static int store_cici(const CICI *f, PyObject *o)
{
    PyObject *c = sub(o, "_cic");
    if (c == NULL)
        return -1;
    int r = -1;
    PyObject *buf = sub(c, "_buf");
    const CIC *k = &f->cic;
    if (buf == NULL)
        goto done;
    for (long long j = 0; j < k->M; j++) {
        PyObject *v = PyFloat_FromDouble(k->buf[j]);
        if (v == NULL || PySequence_SetItem(buf, (Py_ssize_t)j, v) < 0) {
            Py_XDECREF(v);
            goto done;
        }
        Py_DECREF(v);
    }
    if (set_d(o, "_held", f->held) < 0 || set_ll(c, "_i", k->i) < 0
        || set_d(c, "_acc", k->acc) < 0 || set_ll(c, "_n", k->n) < 0)
        goto done;
    r = 0;
done:
    Py_XDECREF(buf);
    Py_DECREF(c);
    return r;
}

/* ------------------------------------------------------ svpwm (_svpwm.py) */
static double clip(double d) { return d < 0.0 ? 0.0 : (d > 1.0 ? 1.0 : d); }

static void svpwm(double u_alpha, double u_beta, double u_dc, double *d)
{
    double u_a = u_alpha;
    double u_b = -0.5 * u_alpha + SQRT3_HALF * u_beta;
    double u_c = -0.5 * u_alpha - SQRT3_HALF * u_beta;
    double hi, lo;
    if (u_a > u_b) {
        hi = u_a;
        lo = u_b;
    } else {
        hi = u_b;
        lo = u_a;
    }
    if (u_c > hi)
        hi = u_c;
    else if (u_c < lo)
        lo = u_c;
    double k = 1.0 / u_dc;
    double off = 0.5 - 0.5 * (hi + lo) * k;
    d[0] = off + u_a * k;
    d[1] = off + u_b * k;
    d[2] = off + u_c * k;
    if ((hi - lo) * k > 1.0 - 1e-12) {
        d[0] = clip(d[0]);
        d[1] = clip(d[1]);
        d[2] = clip(d[2]);
    }
}

/* ------------------------------------------------------------ estimators */
typedef struct {
    /* the Estimator protocol's attributes (controller._api.Estimator) */
    double theta_hat, w_hat, err, i_alpha_f, i_beta_f;
} EST;

/* RotatingHFEstimator and its demodulators (tt-dq, tt-ab, sfhf) */
typedef struct {
    double V_h, wT, inv_norm, f;
    long long k;
    int track;                 /* tt-dq's bpf_tracking */
    double w_h, T_s, B, w0_min; /* its centre, period, bandwidth, lowest centre */
    PLL pll;
    BQ2 bpf;
    FO lpf;      /* tt-dq, sfhf */
    FO2 lpf_ab;  /* tt-ab */
    FO2 hpf;     /* sfhf */
} ROT;

static void rot_publish(EST *e, ROT *r, double th, double f, double err, double i_af,
                        double i_bf)
{
    e->i_alpha_f = i_af;
    e->i_beta_f = i_bf;
    e->theta_hat = th;
    r->f = f;
    e->err = err;
    pll_update(&r->pll, err);
    e->w_hat = r->pll.w_hat;
}

/* controller._filters.bandpass_coefficients */
static void bp_coef(double w_0, double B, double T_s, double *b0, double *a1, double *a2)
{
    double c = w_0 / tan(0.5 * w_0 * T_s);
    double cc = c * c;
    double ww = w_0 * w_0;
    double bc = B * c;
    double inv = 1.0 / (cc + bc + ww);
    *b0 = bc * inv;
    *a1 = 2.0 * (ww - cc) * inv;
    *a2 = (cc - bc + ww) * inv;
}

static void ttdq_update(EST *e, ROT *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = r->pll.theta_hat;
    double c = cos(th);
    double s = sin(th);
    double i_d = c * i_a + s * i_b;
    double i_q = c * i_b - s * i_a;
    double i_dh, i_qh;
    if (r->track) {
        double w_0 = r->w_h - r->pll.w_i;
        if (w_0 < 0.0)
            w_0 = -w_0;
        if (w_0 < r->w0_min)
            w_0 = r->w0_min;
        double b0;
        bp_coef(w_0, r->B, r->T_s, &b0, &r->bpf.a1, &r->bpf.a2);
        r->bpf.b0 = b0;
        r->bpf.b2 = -b0;
    }
    bq2_update(&r->bpf, i_d, i_q, &i_dh, &i_qh);
    double f = fo_update(&r->lpf, i_dh * i_qh);
    double err = f * r->inv_norm;
    double i_df = i_d - i_dh;
    double i_qf = i_q - i_qh;
    rot_publish(e, r, th, f, err, c * i_df - s * i_qf, s * i_df + c * i_qf);
}

static void ttab_update(EST *e, ROT *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = r->pll.theta_hat;
    double i_ah, i_bh, s_2, c_2;
    bq2_update(&r->bpf, i_a, i_b, &i_ah, &i_bh);
    fo2_update(&r->lpf_ab, i_ah * i_bh, 0.5 * (i_ah * i_ah - i_bh * i_bh), &s_2, &c_2);
    double f = s_2 * cos(2.0 * th) - c_2 * sin(2.0 * th);
    double err = f * r->inv_norm;
    rot_publish(e, r, th, f, err, i_a - i_ah, i_b - i_bh);
}

static void sfhf_update(EST *e, ROT *r, long long k, double i_a, double i_b)
{
    r->k = k;
    double th = r->pll.theta_hat;
    double ph = py_mod((double)k * r->wT, 2.0 * M_PI);
    double c_h = cos(ph);
    double s_h = sin(ph);
    double i_ah, i_bh, x_p, y_p;
    bq2_update(&r->bpf, i_a, i_b, &i_ah, &i_bh);
    fo2_update(&r->hpf, c_h * i_ah + s_h * i_bh, c_h * i_bh - s_h * i_ah, &x_p, &y_p);
    double i_an = c_h * x_p - s_h * y_p;
    double i_bn = s_h * x_p + c_h * y_p;
    double ref = 2.0 * th - ph;
    double c_r = cos(ref);
    double s_r = sin(ref);
    double f = fo_update(&r->lpf, -(i_an * c_r + i_bn * s_r));
    double err = f * r->inv_norm;
    rot_publish(e, r, th, f, err, i_a - i_ah, i_b - i_bh);
}

static void rot_injection(const ROT *r, double *u_a, double *u_b)
{
    double ph = ((double)r->k + 1.5) * r->wT;
    *u_a = r->V_h * cos(ph);
    *u_b = r->V_h * sin(ph);
}

/* SquareWaveEstimator (Xue) */
typedef struct {
    int cic;
    double U_h, t_comp, k_err;
    double e_alpha, e_beta, u_next_a, u_next_b;
    double sg0, sg1, sg2, c0, c1, c2, s0, s1, s2, ha1, hb1;
    double held[4];
    long long env_n, n, n_tot;
    double ia1, ib1, id1, iq1, id2, iq2;
    LUEN obs;
    CICI interp[4];
} SQW;

static void sqw_update(EST *e, SQW *q, double i_a, double i_b, double torque)
{
    long long n = q->n;
    int fresh = 0;
    double E_a = 0.0, E_b = 0.0, u_c = 0.0, u_s = 0.0;
    if (n >= 1) {
        double h_a = 0.5 * (i_a - q->ia1);
        double h_b = 0.5 * (i_b - q->ib1);
        if (n >= 3 && q->sg1 < 0.0) {
            E_a = 0.5 * (q->ha1 - h_a);
            E_b = 0.5 * (q->hb1 - h_b);
            u_c = 0.5 * (q->c1 + q->c2);
            u_s = 0.5 * (q->s1 + q->s2);
            fresh = 1;
        }
        q->ha1 = h_a;
        q->hb1 = h_b;
    }
    double err = 0.0;
    if (fresh && q->env_n == 0) {
        cici_prime(&q->interp[0], E_a);
        cici_prime(&q->interp[1], E_b);
        cici_prime(&q->interp[2], u_c);
        cici_prime(&q->interp[3], u_s);
    }
    if (fresh)
        q->env_n += 1;
    if (q->env_n) {
        double e_a, e_b, v_c, v_s;
        if (q->cic) {
            e_a = cici_step(&q->interp[0], fresh, E_a);
            e_b = cici_step(&q->interp[1], fresh, E_b);
            v_c = cici_step(&q->interp[2], fresh, u_c);
            v_s = cici_step(&q->interp[3], fresh, u_s);
        } else {
            if (fresh) {
                q->held[0] = E_a;
                q->held[1] = E_b;
                q->held[2] = u_c;
                q->held[3] = u_s;
            }
            e_a = q->held[0];
            e_b = q->held[1];
            v_c = q->held[2];
            v_s = q->held[3];
        }
        q->e_alpha = e_a;
        q->e_beta = e_b;
        double den = sqrt((e_a * e_a + e_b * e_b) * (v_c * v_c + v_s * v_s));
        if (den > 0.0)
            err = (e_b * v_c - e_a * v_s) / den * q->k_err;
    }
    e->err = err;

    luen_step(&q->obs, err, torque);
    double th = q->obs.theta_hat;
    double w = q->obs.w_hat;
    e->theta_hat = th;
    e->w_hat = w;

    double sgn = q->sg0 != 0.0 ? -q->sg0 : 1.0;
    double phi = th + q->t_comp * w;
    double c = cos(phi);
    double s = sin(phi);
    double uh = sgn * q->U_h;
    q->u_next_a = uh * c;
    q->u_next_b = uh * s;
    q->sg2 = q->sg1;
    q->c2 = q->c1;
    q->s2 = q->s1;
    q->sg1 = q->sg0;
    q->c1 = q->c0;
    q->s1 = q->s0;
    q->sg0 = sgn;
    q->c0 = c;
    q->s0 = s;

    double ct = cos(th);
    double st = sin(th);
    double i_d = ct * i_a + st * i_b;
    double i_q = ct * i_b - st * i_a;
    double i_df, i_qf;
    if (q->n_tot >= 2) {
        i_df = 0.25 * (3.0 * i_d + 2.0 * q->id1 - q->id2);
        i_qf = 0.25 * (3.0 * i_q + 2.0 * q->iq1 - q->iq2);
    } else {
        i_df = i_d;
        i_qf = i_q;
    }
    e->i_alpha_f = ct * i_df - st * i_qf;
    e->i_beta_f = st * i_df + ct * i_qf;
    q->id2 = q->id1;
    q->iq2 = q->iq1;
    q->id1 = i_d;
    q->iq1 = i_q;
    q->ia1 = i_a;
    q->ib1 = i_b;
    q->n = n + 1;
    q->n_tot += 1;
}

/* the CIC of this period would re-anchor its integrator (Python's sum()) */
static int sqw_needs_python(const SQW *q)
{
    if (!q->cic)
        return 0;
    for (int j = 0; j < 4; j++)
        if (q->interp[j].cic.n + 1 >= CIC_REANCHOR)
            return 1;
    return 0;
}

static int get_pair(PyObject *o, const char *name, double *a, double *b, Py_ssize_t n_exp,
                    double *rest)
{
    PyObject *t = PyObject_GetAttrString(o, name);
    if (t == NULL)
        return -1;
    int r = -1;
    if (!PyTuple_Check(t) || PyTuple_GET_SIZE(t) != n_exp) {
        PyErr_Format(PyExc_TypeError, "compiled controller: %s is not a %zd-tuple", name, n_exp);
        goto done;
    }
    for (Py_ssize_t j = 0; j < n_exp; j++) {
        double v = PyFloat_AsDouble(PyTuple_GET_ITEM(t, j));
        if (v == -1.0 && PyErr_Occurred())
            goto done;
        if (j == 0 && a)
            *a = v;
        else if (j == 1 && b)
            *b = v;
        if (rest)
            rest[j] = v;
    }
    r = 0;
done:
    Py_DECREF(t);
    return r;
}

static int load_sqw(SQW *q, PyObject *o)
{
    TRY(get_bool(o, "cic", &q->cic));
    TRY(get_d(o, "U_h", &q->U_h)); TRY(get_d(o, "_t_comp", &q->t_comp));
    TRY(get_d(o, "_k_err", &q->k_err));
    TRY(get_d(o, "e_alpha", &q->e_alpha)); TRY(get_d(o, "e_beta", &q->e_beta));
    TRY(get_pair(o, "_u_next", &q->u_next_a, &q->u_next_b, 2, NULL));
    TRY(get_d(o, "_sg0", &q->sg0)); TRY(get_d(o, "_sg1", &q->sg1)); TRY(get_d(o, "_sg2", &q->sg2));
    TRY(get_d(o, "_c0", &q->c0)); TRY(get_d(o, "_c1", &q->c1)); TRY(get_d(o, "_c2", &q->c2));
    TRY(get_d(o, "_s0", &q->s0)); TRY(get_d(o, "_s1", &q->s1)); TRY(get_d(o, "_s2", &q->s2));
    TRY(get_d(o, "_ha1", &q->ha1)); TRY(get_d(o, "_hb1", &q->hb1));
    TRY(get_pair(o, "_held", NULL, NULL, 4, q->held));
    TRY(get_ll(o, "_env_n", &q->env_n)); TRY(get_ll(o, "_n", &q->n));
    TRY(get_ll(o, "_n_tot", &q->n_tot));
    TRY(get_d(o, "_ia1", &q->ia1)); TRY(get_d(o, "_ib1", &q->ib1));
    TRY(get_d(o, "_id1", &q->id1)); TRY(get_d(o, "_iq1", &q->iq1));
    TRY(get_d(o, "_id2", &q->id2)); TRY(get_d(o, "_iq2", &q->iq2));
    PyObject *obs = sub(o, "observer");
    if (obs == NULL)
        return -1;
    int r = load_luen(&q->obs, obs);
    Py_DECREF(obs);
    TRY(r);
    PyObject *ip = sub(o, "_interp");
    if (ip == NULL)
        return -1;
    r = 0;
    for (int j = 0; j < 4 && r == 0; j++) {
        PyObject *f = PySequence_GetItem(ip, j);
        r = f == NULL ? -1 : load_cici(&q->interp[j], f);
        Py_XDECREF(f);
    }
    Py_DECREF(ip);
    return r;
}

static int store_sqw(const SQW *q, PyObject *o)
{
    TRY(set_d(o, "e_alpha", q->e_alpha)); TRY(set_d(o, "e_beta", q->e_beta));
    TRY(set_obj(o, "_u_next", Py_BuildValue("(dd)", q->u_next_a, q->u_next_b)));
    TRY(set_d(o, "_sg0", q->sg0)); TRY(set_d(o, "_sg1", q->sg1)); TRY(set_d(o, "_sg2", q->sg2));
    TRY(set_d(o, "_c0", q->c0)); TRY(set_d(o, "_c1", q->c1)); TRY(set_d(o, "_c2", q->c2));
    TRY(set_d(o, "_s0", q->s0)); TRY(set_d(o, "_s1", q->s1)); TRY(set_d(o, "_s2", q->s2));
    TRY(set_d(o, "_ha1", q->ha1)); TRY(set_d(o, "_hb1", q->hb1));
    TRY(set_obj(o, "_held",
                Py_BuildValue("(dddd)", q->held[0], q->held[1], q->held[2], q->held[3])));
    TRY(set_ll(o, "_env_n", q->env_n)); TRY(set_ll(o, "_n", q->n));
    TRY(set_ll(o, "_n_tot", q->n_tot));
    TRY(set_d(o, "_ia1", q->ia1)); TRY(set_d(o, "_ib1", q->ib1));
    TRY(set_d(o, "_id1", q->id1)); TRY(set_d(o, "_iq1", q->iq1));
    TRY(set_d(o, "_id2", q->id2)); TRY(set_d(o, "_iq2", q->iq2));
    PyObject *obs = sub(o, "observer");
    if (obs == NULL)
        return -1;
    int r = store_luen(&q->obs, obs);
    Py_DECREF(obs);
    TRY(r);
    PyObject *ip = sub(o, "_interp");
    if (ip == NULL)
        return -1;
    for (int j = 0; j < 4 && r == 0; j++) {
        PyObject *f = PySequence_GetItem(ip, j);
        r = f == NULL ? -1 : store_cici(&q->interp[j], f);
        Py_XDECREF(f);
    }
    Py_DECREF(ip);
    return r;
}

/* SensoredEstimator: the truth passes through (the only reader of it) */
static void sens_update(EST *e, double i_a, double i_b, double theta_e, double w_e)
{
    e->theta_hat = theta_e;
    e->w_hat = w_e;
    e->i_alpha_f = i_a;
    e->i_beta_f = i_b;
}

/* ------------------------------------------- FluxObserver (_flux_observer.py) */
typedef struct {
    double L_d, L_q, psi_f, T_s, w_min, k_i, kp, ki_T, zT, rT2, dL;
    double psi_alpha, psi_beta, ia1, ib1, theta_hat, w_hat, eps, accel, th_next;
    int init;
} FLUX;

static double flux_k1T(const FLUX *o, double w)
{
    double a = w >= 0.0 ? w : -w;
    if (a < o->w_min)
        a = o->w_min;
    double g = o->zT * a;
    return g < 0.5 ? g : 0.5;
}

static void flux_predict(FLUX *o, double i_a, double i_b, double u_a, double u_b, double c,
                         double s)
{
    if (o->init) {
        double i_d = c * i_a + s * i_b;
        double i_q = c * i_b - s * i_a;
        double p_d = o->psi_f + o->L_d * i_d;
        double p_q = o->L_q * i_q;
        o->psi_alpha = c * p_d - s * p_q;
        o->psi_beta = s * p_d + c * p_q;
        o->init = 0;
    } else {
        double T = o->T_s;
        double r = o->rT2;
        o->psi_alpha += T * u_a - r * (i_a + o->ia1);
        o->psi_beta += T * u_b - r * (i_b + o->ib1);
    }
    o->ia1 = i_a;
    o->ib1 = i_b;
}

static void flux_error(const FLUX *o, double i_alpha, double i_beta, double c, double s,
                       double *e_d, double *e_q, double *a_d, double *a_q, double *den)
{
    double i_d = c * i_alpha + s * i_beta;
    double i_q = c * i_beta - s * i_alpha;
    double pa = o->psi_alpha;
    double pb = o->psi_beta;
    *e_d = o->psi_f + o->L_d * i_d - (c * pa + s * pb);
    *e_q = o->L_q * i_q - (c * pb - s * pa);
    *a_d = o->psi_f + o->dL * i_d;
    *a_q = -o->dL * i_q;
    *den = *a_d * *a_d + *a_q * *a_q;
}

static void flux_update(FLUX *o, double i_alpha, double i_beta, double u_alpha, double u_beta)
{
    double th = o->th_next;
    double c = cos(th);
    double s = sin(th);
    flux_predict(o, i_alpha, i_beta, u_alpha, u_beta, c, s);
    double pa = o->psi_alpha;
    double pb = o->psi_beta;
    double e_d, e_q, a_d, a_q, den, x, eps;
    flux_error(o, i_alpha, i_beta, c, s, &e_d, &e_q, &a_d, &a_q, &den);
    if (den > 0.0) {
        double inv = 1.0 / den;
        x = (e_d * a_d + e_q * a_q) * inv;
        eps = (e_d * a_q - e_q * a_d) * inv;
    } else {
        x = eps = 0.0;
    }
    double g = 2.0 * flux_k1T(o, o->w_hat) * x;
    double cd = g * a_d;
    double cq = g * a_q;
    o->psi_alpha = pa + c * cd - s * cq;
    o->psi_beta = pb + s * cd + c * cq;
    double w_i = o->w_hat + o->ki_T * eps;
    o->w_hat = w_i;
    o->eps = eps;
    o->accel = o->k_i * eps;
    o->theta_hat = th;
    th += o->T_s * (w_i + o->kp * eps);
    if (th >= TWO_PI || th < 0.0)
        th = py_mod(th, TWO_PI);
    o->th_next = th;
}

static void flux_update_slaved(FLUX *o, double i_alpha, double i_beta, double u_alpha,
                               double u_beta, double theta, double w)
{
    double c = cos(theta);
    double s = sin(theta);
    flux_predict(o, i_alpha, i_beta, u_alpha, u_beta, c, s);
    double pa = o->psi_alpha;
    double pb = o->psi_beta;
    double e_d, e_q, a_d, a_q, den;
    flux_error(o, i_alpha, i_beta, c, s, &e_d, &e_q, &a_d, &a_q, &den);
    o->eps = den > 0.0 ? (e_d * a_q - e_q * a_d) / den : 0.0;
    o->accel = 0.0;
    double g = flux_k1T(o, w);
    o->psi_alpha = pa + g * (c * e_d - s * e_q);
    o->psi_beta = pb + g * (s * e_d + c * e_q);
    o->w_hat = w;
    double th = py_mod(theta, TWO_PI);
    o->theta_hat = th;
    th += o->T_s * w;
    if (th >= TWO_PI || th < 0.0)
        th = py_mod(th, TWO_PI);
    o->th_next = th;
}

static int load_flux(FLUX *f, PyObject *o)
{
    TRY(get_d(o, "L_d", &f->L_d)); TRY(get_d(o, "L_q", &f->L_q));
    TRY(get_d(o, "psi_f", &f->psi_f)); TRY(get_d(o, "T_s", &f->T_s));
    TRY(get_d(o, "w_min", &f->w_min)); TRY(get_d(o, "k_i", &f->k_i));
    TRY(get_d(o, "_kp", &f->kp)); TRY(get_d(o, "_ki_T", &f->ki_T)); TRY(get_d(o, "_zT", &f->zT));
    TRY(get_d(o, "_rT2", &f->rT2)); TRY(get_d(o, "_dL", &f->dL));
    TRY(get_d(o, "psi_alpha", &f->psi_alpha)); TRY(get_d(o, "psi_beta", &f->psi_beta));
    TRY(get_d(o, "_ia1", &f->ia1)); TRY(get_d(o, "_ib1", &f->ib1));
    TRY(get_d(o, "theta_hat", &f->theta_hat)); TRY(get_d(o, "w_hat", &f->w_hat));
    TRY(get_d(o, "eps", &f->eps)); TRY(get_d(o, "accel", &f->accel));
    TRY(get_d(o, "_th_next", &f->th_next)); TRY(get_bool(o, "_init", &f->init));
    return 0;
}

static int store_flux(const FLUX *f, PyObject *o)
{
    TRY(set_d(o, "psi_alpha", f->psi_alpha)); TRY(set_d(o, "psi_beta", f->psi_beta));
    TRY(set_d(o, "_ia1", f->ia1)); TRY(set_d(o, "_ib1", f->ib1));
    TRY(set_d(o, "theta_hat", f->theta_hat)); TRY(set_d(o, "w_hat", f->w_hat));
    TRY(set_d(o, "eps", f->eps)); TRY(set_d(o, "accel", f->accel));
    TRY(set_d(o, "_th_next", f->th_next));
    TRY(set_obj(o, "_init", PyBool_FromLong(f->init)));
    return 0;
}

/* --------------------------------------- TransitionBand (_hybrid.py) */
typedef struct { double w_lo, w_mid, w_hi, h; } BAND;

static double band_play(const BAND *b, double y, double w)
{
    double s = w >= 0.0 ? w : -w;
    if (s < y)
        return s;
    if (s - b->h > y)
        return s - b->h;
    return y;
}

static void band_weights(const BAND *b, double y, double *lam_out, double *g_out)
{
    double lam = (y - b->w_lo) / (b->w_mid - b->w_lo);
    double g = (b->w_hi - y) / (b->w_hi - b->w_mid);
    *lam_out = lam <= 0.0 ? 0.0 : (lam >= 1.0 ? 1.0 : lam);
    *g_out = g <= 0.0 ? 0.0 : (g >= 1.0 ? 1.0 : g);
}

/* HybridEstimator's own state (its injection estimator and observer are the core's
 * ROT or SQW and the FLUX below) */
typedef struct {
    int hf_kind;          /* KIND_TTDQ (_PllTracker) or KIND_SQW (_LuenbergerTracker) */
    EST hf;               /* the injection estimator's Estimator attributes */
    FLUX obs;
    BAND band;
    double tr_T_s, tr_k_x; /* the tracker's constants */
    double weight, gain, y;
} HYB;

/* ------------------------------------------------------------ the core */
#define N_MEAS 7
#define N_OUT 11
static const char *MEAS_FIELDS[N_MEAS] = {"k", "i_a", "i_b", "i_c", "u_dc", "theta_e", "w_e"};
static const char *OUT_FIELDS[N_OUT] = {"k", "d_a", "d_b", "d_c", "enable", "theta_hat",
                                        "w_hat", "err", "mode", "i_d", "i_q"};

typedef struct {
    PyObject_HEAD
    int kind;
    int raw_feedback;
    int dirty;  /* stepped since the last store() */
    int holds;  /* the core holds the states (loaded, and Python has not changed them since) */
    PyObject *state;     /* bind(): the controller's __dict__ */
    PyObject *fallback;  /* bind(): the Python step, for the periods the core leaves */
    /* the seam's classes and their slots' offsets (-1: read by name) */
    PyTypeObject *meas_t, *out_t;
    Py_ssize_t meas_off[N_MEAS], out_off[N_OUT];
    /* controller constants */
    double n_p, L_d, L_q, psi_f, k_tau, i_max, tau_max, t_delay;
    long long n_align, n_settle;
    /* controller states */
    long long mode, n_mode;
    int settled, has_i_ref;
    double i_ref_d, i_ref_q;
    double w_m_ref, i_d_ref, i_q_ref, tau_ref, w_m_hat, u_d, u_q, u_a1, u_b1, u_a2, u_b2;
    PI pi_d, pi_q, pi_w;
    FO lpf_w;
    /* estimator: its Estimator attributes; the rotating or square-wave state (of the
     * hybrid's injection estimator for a hybrid) and the hybrid's own */
    EST est;
    ROT rot;
    SQW sqw;
    HYB hyb;
} Core;

static Py_ssize_t slot_offset(PyTypeObject *tp, const char *name)
{
    PyObject *d = PyObject_GetAttrString((PyObject *)tp, name);
    Py_ssize_t off = -1;
    if (d == NULL) {
        PyErr_Clear();
        return -1;
    }
    if (Py_IS_TYPE(d, &PyMemberDescr_Type)) {
        PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
        if (m->type == T_OBJECT_EX && !(m->flags & READONLY))
            off = m->offset;
    }
    Py_DECREF(d);
    return off;
}

static int Core_traverse(Core *self, visitproc visit, void *arg)
{
    Py_VISIT(self->state);
    Py_VISIT(self->fallback);
    Py_VISIT(self->meas_t);
    Py_VISIT(self->out_t);
    return 0;
}

static int Core_clear(Core *self)
{
    Py_CLEAR(self->state);
    Py_CLEAR(self->fallback);
    Py_CLEAR(self->meas_t);
    Py_CLEAR(self->out_t);
    return 0;
}

static void Core_dealloc(Core *self)
{
    PyObject_GC_UnTrack(self);
    Core_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int Core_init(Core *self, PyObject *args, PyObject *kwds)
{
    static char *kwlist[] = {"kind", "measurement", "output", NULL};
    int kind;
    PyObject *mt, *ot;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "iO!O!", kwlist, &kind, &PyType_Type, &mt,
                                     &PyType_Type, &ot))
        return -1;
    if (kind < KIND_TTDQ || kind > KIND_HYB_SQW) {
        PyErr_Format(PyExc_ValueError, "compiled controller: unknown estimator kind %d", kind);
        return -1;
    }
    self->kind = kind;
    self->hyb.hf_kind = kind == KIND_HYB_SQW ? KIND_SQW : KIND_TTDQ;
    Py_INCREF(mt);
    Py_XSETREF(self->meas_t, (PyTypeObject *)mt);
    Py_INCREF(ot);
    Py_XSETREF(self->out_t, (PyTypeObject *)ot);
    for (int j = 0; j < N_MEAS; j++)
        self->meas_off[j] = slot_offset(self->meas_t, MEAS_FIELDS[j]);
    int all = 1;
    for (int j = 0; j < N_OUT; j++) {
        self->out_off[j] = slot_offset(self->out_t, OUT_FIELDS[j]);
        all = all && self->out_off[j] >= 0;
    }
    if (!all) /* not a slotted class: outputs are built by calling it */
        for (int j = 0; j < N_OUT; j++)
            self->out_off[j] = -1;
    return 0;
}

static PyObject *dict_item(PyObject *d, const char *name) /* borrowed */
{
    PyObject *v = PyDict_GetItemString(d, name);
    if (v == NULL && !PyErr_Occurred())
        PyErr_Format(PyExc_AttributeError, "compiled controller: no attribute %s", name);
    return v;
}

static int dict_d(PyObject *d, const char *name, double *out)
{
    PyObject *v = dict_item(d, name);
    if (v == NULL)
        return -1;
    *out = PyFloat_AsDouble(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static int dict_ll(PyObject *d, const char *name, long long *out)
{
    PyObject *v = dict_item(d, name);
    if (v == NULL)
        return -1;
    *out = PyLong_AsLongLong(v);
    return (*out == -1 && PyErr_Occurred()) ? -1 : 0;
}

static int dict_set(PyObject *d, const char *name, PyObject *v)
{
    if (v == NULL)
        return -1;
    int r = PyDict_SetItemString(d, name, v);
    Py_DECREF(v);
    return r;
}

static int load_est(Core *self, int kind, EST *e, PyObject *o);
static int store_est(Core *self, int kind, const EST *e, PyObject *o);

static int load_hyb(Core *self, HYB *h, PyObject *o)
{
    TRY(get_d(o, "weight", &h->weight)); TRY(get_d(o, "gain", &h->gain)); TRY(get_d(o, "y", &h->y));
    PyObject *x;
    int rc;
    x = sub(o, "band");
    if (x == NULL)
        return -1;
    rc = (get_d(x, "w_lo", &h->band.w_lo) < 0 || get_d(x, "w_mid", &h->band.w_mid) < 0
          || get_d(x, "w_hi", &h->band.w_hi) < 0 || get_d(x, "h", &h->band.h) < 0) ? -1 : 0;
    Py_DECREF(x);
    TRY(rc);
    x = sub(o, "tracker");
    if (x == NULL)
        return -1;
    rc = h->hf_kind == KIND_TTDQ ? get_d(x, "T_s", &h->tr_T_s) : get_d(x, "_k_x", &h->tr_k_x);
    Py_DECREF(x);
    TRY(rc);
    x = sub(o, "observer");
    if (x == NULL)
        return -1;
    rc = load_flux(&h->obs, x);
    Py_DECREF(x);
    TRY(rc);
    x = sub(o, "hf");
    if (x == NULL)
        return -1;
    rc = load_est(self, h->hf_kind, &h->hf, x);
    Py_DECREF(x);
    return rc;
}

static int store_hyb(Core *self, const HYB *h, PyObject *o)
{
    TRY(set_d(o, "weight", h->weight)); TRY(set_d(o, "gain", h->gain)); TRY(set_d(o, "y", h->y));
    PyObject *x = sub(o, "observer");
    if (x == NULL)
        return -1;
    int rc = store_flux(&h->obs, x);
    Py_DECREF(x);
    TRY(rc);
    x = sub(o, "hf");
    if (x == NULL)
        return -1;
    rc = store_est(self, h->hf_kind, &h->hf, x);
    Py_DECREF(x);
    return rc;
}

static int load_est(Core *self, int kind, EST *e, PyObject *o)
{
    TRY(get_d(o, "theta_hat", &e->theta_hat)); TRY(get_d(o, "w_hat", &e->w_hat));
    TRY(get_d(o, "err", &e->err));
    TRY(get_d(o, "i_alpha_f", &e->i_alpha_f)); TRY(get_d(o, "i_beta_f", &e->i_beta_f));
    if (kind == KIND_SENSORED)
        return 0;
    if (kind == KIND_HYB_TTDQ || kind == KIND_HYB_SQW)
        return load_hyb(self, &self->hyb, o);
    if (kind == KIND_SQW)
        return load_sqw(&self->sqw, o);
    ROT *r = &self->rot;
    TRY(get_d(o, "V_h", &r->V_h)); TRY(get_d(o, "wT", &r->wT));
    TRY(get_d(o, "_inv_norm", &r->inv_norm)); TRY(get_d(o, "f", &r->f));
    TRY(get_ll(o, "_k", &r->k));
    r->track = 0;
    if (kind == KIND_TTDQ) {
        TRY(get_bool(o, "bpf_tracking", &r->track));
        TRY(get_d(o, "w_h", &r->w_h)); TRY(get_d(o, "T_s", &r->T_s));
        TRY(get_d(o, "bpf_B", &r->B)); TRY(get_d(o, "_w0_min", &r->w0_min));
    }
    PyObject *x;
    int rc;
#define LOAD_SUB(name, fn, dst) \
    x = sub(o, name); if (x == NULL) return -1; rc = fn(dst, x); Py_DECREF(x); TRY(rc);
    LOAD_SUB("pll", load_pll, &r->pll);
    LOAD_SUB("_bpf", load_bq2, &r->bpf);
    if (kind == KIND_TTAB) {
        LOAD_SUB("_lpf", load_fo2, &r->lpf_ab);
    } else {
        LOAD_SUB("_lpf", load_fo, &r->lpf);
    }
    if (kind == KIND_SFHF) {
        LOAD_SUB("_hpf", load_fo2, &r->hpf);
    }
#undef LOAD_SUB
    return 0;
}

static int store_est(Core *self, int kind, const EST *e, PyObject *o)
{
    TRY(set_d(o, "theta_hat", e->theta_hat)); TRY(set_d(o, "w_hat", e->w_hat));
    TRY(set_d(o, "err", e->err));
    TRY(set_d(o, "i_alpha_f", e->i_alpha_f)); TRY(set_d(o, "i_beta_f", e->i_beta_f));
    if (kind == KIND_SENSORED)
        return 0;
    if (kind == KIND_HYB_TTDQ || kind == KIND_HYB_SQW)
        return store_hyb(self, &self->hyb, o);
    if (kind == KIND_SQW)
        return store_sqw(&self->sqw, o);
    ROT *r = &self->rot;
    TRY(set_d(o, "f", r->f)); TRY(set_ll(o, "_k", r->k));
    PyObject *x;
    int rc;
#define STORE_SUB(name, fn, src) \
    x = sub(o, name); if (x == NULL) return -1; rc = fn(src, x); Py_DECREF(x); TRY(rc);
    STORE_SUB("pll", store_pll, &r->pll);
    if (r->track) {
        STORE_SUB("_bpf", store_bq2_tuned, &r->bpf);
    } else {
        STORE_SUB("_bpf", store_bq2, &r->bpf);
    }
    if (kind == KIND_TTAB) {
        STORE_SUB("_lpf", store_fo2, &r->lpf_ab);
    } else {
        STORE_SUB("_lpf", store_fo, &r->lpf);
    }
    if (kind == KIND_SFHF) {
        STORE_SUB("_hpf", store_fo2, &r->hpf);
    }
#undef STORE_SUB
    return 0;
}

/* load(d): every constant and state from the controller's attribute dict d */
static PyObject *Core_load(Core *self, PyObject *d)
{
    if (!PyDict_Check(d)) {
        PyErr_SetString(PyExc_TypeError, "load() takes the controller's __dict__");
        return NULL;
    }
    PyObject *m = dict_item(d, "motor");
    if (m == NULL)
        return NULL;
    long long n_p;
    if (get_ll(m, "n_p", &n_p) < 0 || get_d(m, "L_d", &self->L_d) < 0
        || get_d(m, "L_q", &self->L_q) < 0 || get_d(m, "psi_f", &self->psi_f) < 0)
        return NULL;
    self->n_p = (double)n_p;
    PyObject *v;
    if (dict_d(d, "k_tau", &self->k_tau) < 0 || dict_d(d, "i_max", &self->i_max) < 0
        || dict_d(d, "tau_max", &self->tau_max) < 0 || dict_d(d, "t_delay", &self->t_delay) < 0
        || dict_ll(d, "n_align", &self->n_align) < 0 || dict_ll(d, "n_settle", &self->n_settle) < 0
        || dict_ll(d, "mode", &self->mode) < 0 || dict_ll(d, "_n_mode", &self->n_mode) < 0
        || dict_d(d, "w_m_ref", &self->w_m_ref) < 0 || dict_d(d, "i_d_ref", &self->i_d_ref) < 0
        || dict_d(d, "i_q_ref", &self->i_q_ref) < 0 || dict_d(d, "tau_ref", &self->tau_ref) < 0
        || dict_d(d, "w_m_hat", &self->w_m_hat) < 0 || dict_d(d, "u_d", &self->u_d) < 0
        || dict_d(d, "u_q", &self->u_q) < 0 || dict_d(d, "_u_a1", &self->u_a1) < 0
        || dict_d(d, "_u_b1", &self->u_b1) < 0 || dict_d(d, "_u_a2", &self->u_a2) < 0
        || dict_d(d, "_u_b2", &self->u_b2) < 0)
        return NULL;
    if ((v = dict_item(d, "raw_feedback")) == NULL || (self->raw_feedback = PyObject_IsTrue(v)) < 0)
        return NULL;
    if ((v = dict_item(d, "_settled")) == NULL || (self->settled = PyObject_IsTrue(v)) < 0)
        return NULL;
    if ((v = dict_item(d, "_i_ref")) == NULL)
        return NULL;
    self->has_i_ref = v != Py_None;
    if (self->has_i_ref) {
        if (!PyTuple_Check(v) || PyTuple_GET_SIZE(v) != 2) {
            PyErr_SetString(PyExc_TypeError, "compiled controller: _i_ref is not a pair");
            return NULL;
        }
        self->i_ref_d = PyFloat_AsDouble(PyTuple_GET_ITEM(v, 0));
        self->i_ref_q = PyFloat_AsDouble(PyTuple_GET_ITEM(v, 1));
        if (PyErr_Occurred())
            return NULL;
    }
    if ((v = dict_item(d, "pi_d")) == NULL || load_pi(&self->pi_d, v) < 0)
        return NULL;
    if ((v = dict_item(d, "pi_q")) == NULL || load_pi(&self->pi_q, v) < 0)
        return NULL;
    if ((v = dict_item(d, "pi_w")) == NULL || load_pi(&self->pi_w, v) < 0)
        return NULL;
    if ((v = dict_item(d, "lpf_w")) == NULL || load_fo(&self->lpf_w, v) < 0)
        return NULL;
    if ((v = dict_item(d, "estimator")) == NULL || load_est(self, self->kind, &self->est, v) < 0)
        return NULL;
    self->dirty = 0;
    Py_RETURN_NONE;
}

/* store(d): the states back into the controller's attribute dict d and its objects */
static PyObject *Core_store(Core *self, PyObject *d)
{
    if (!PyDict_Check(d)) {
        PyErr_SetString(PyExc_TypeError, "store() takes the controller's __dict__");
        return NULL;
    }
    PyObject *v;
    if (dict_set(d, "mode", PyLong_FromLongLong(self->mode)) < 0
        || dict_set(d, "_n_mode", PyLong_FromLongLong(self->n_mode)) < 0
        || dict_set(d, "w_m_ref", PyFloat_FromDouble(self->w_m_ref)) < 0
        || dict_set(d, "i_d_ref", PyFloat_FromDouble(self->i_d_ref)) < 0
        || dict_set(d, "i_q_ref", PyFloat_FromDouble(self->i_q_ref)) < 0
        || dict_set(d, "tau_ref", PyFloat_FromDouble(self->tau_ref)) < 0
        || dict_set(d, "w_m_hat", PyFloat_FromDouble(self->w_m_hat)) < 0
        || dict_set(d, "u_d", PyFloat_FromDouble(self->u_d)) < 0
        || dict_set(d, "u_q", PyFloat_FromDouble(self->u_q)) < 0
        || dict_set(d, "_u_a1", PyFloat_FromDouble(self->u_a1)) < 0
        || dict_set(d, "_u_b1", PyFloat_FromDouble(self->u_b1)) < 0
        || dict_set(d, "_u_a2", PyFloat_FromDouble(self->u_a2)) < 0
        || dict_set(d, "_u_b2", PyFloat_FromDouble(self->u_b2)) < 0
        || dict_set(d, "_settled", PyBool_FromLong(self->settled)) < 0)
        return NULL;
    if ((v = dict_item(d, "pi_d")) == NULL || store_pi(&self->pi_d, v) < 0)
        return NULL;
    if ((v = dict_item(d, "pi_q")) == NULL || store_pi(&self->pi_q, v) < 0)
        return NULL;
    if ((v = dict_item(d, "pi_w")) == NULL || store_pi(&self->pi_w, v) < 0)
        return NULL;
    if ((v = dict_item(d, "lpf_w")) == NULL || store_fo(&self->lpf_w, v) < 0)
        return NULL;
    if ((v = dict_item(d, "estimator")) == NULL
        || store_est(self, self->kind, &self->est, v) < 0)
        return NULL;
    self->dirty = 0;
    Py_RETURN_NONE;
}

/* one field of a measurement: the slot read directly, or the attribute */
static PyObject *meas_field(Core *self, PyObject *meas, int j) /* new reference */
{
    if (Py_TYPE(meas) == self->meas_t && self->meas_off[j] >= 0) {
        PyObject *v = *(PyObject **)((char *)meas + self->meas_off[j]);
        if (v != NULL) {
            Py_INCREF(v);
            return v;
        }
    }
    return PyObject_GetAttrString(meas, MEAS_FIELDS[j]);
}

static int meas_double(Core *self, PyObject *meas, int j, double *out)
{
    PyObject *v = meas_field(self, meas, j);
    if (v == NULL)
        return -1;
    *out = PyFloat_AsDouble(v);
    Py_DECREF(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static PyObject *make_output(Core *self, PyObject *k, double d_a, double d_b, double d_c,
                             int enable, double theta_hat, double w_hat, double err,
                             long long mode, double i_d, double i_q)
{
    PyObject *v[N_OUT];
    v[0] = k;
    Py_INCREF(k);
    v[1] = PyFloat_FromDouble(d_a);
    v[2] = PyFloat_FromDouble(d_b);
    v[3] = PyFloat_FromDouble(d_c);
    v[4] = PyBool_FromLong(enable);
    v[5] = PyFloat_FromDouble(theta_hat);
    v[6] = PyFloat_FromDouble(w_hat);
    v[7] = PyFloat_FromDouble(err);
    v[8] = PyLong_FromLongLong(mode);
    v[9] = PyFloat_FromDouble(i_d);
    v[10] = PyFloat_FromDouble(i_q);
    int ok = 1;
    for (int j = 0; j < N_OUT; j++)
        ok = ok && v[j] != NULL;
    PyObject *out = NULL;
    if (ok && self->out_off[0] >= 0) {
        /* a slotted (frozen) dataclass: fill its slots as its __init__ would */
        out = self->out_t->tp_alloc(self->out_t, 0);
        if (out != NULL) {
            for (int j = 0; j < N_OUT; j++) {
                *(PyObject **)((char *)out + self->out_off[j]) = v[j];
                v[j] = NULL;
            }
        }
    } else if (ok) {
        out = PyObject_Vectorcall((PyObject *)self->out_t, v, N_OUT, NULL);
    }
    for (int j = 0; j < N_OUT; j++)
        Py_XDECREF(v[j]);
    return out;
}

static void hyb_update(Core *self, long long k, double i_alpha, double i_beta,
                       double u_alpha, double u_beta, int running);

static void est_update(Core *self, int kind, EST *e, long long k, double i_alpha,
                       double i_beta, double th_e, double w_e, double u_alpha, double u_beta,
                       int running)
{
    switch (kind) {
    case KIND_TTDQ:
        ttdq_update(e, &self->rot, k, i_alpha, i_beta);
        break;
    case KIND_TTAB:
        ttab_update(e, &self->rot, k, i_alpha, i_beta);
        break;
    case KIND_SFHF:
        sfhf_update(e, &self->rot, k, i_alpha, i_beta);
        break;
    case KIND_SQW:
        sqw_update(e, &self->sqw, i_alpha, i_beta, self->tau_ref);
        break;
    case KIND_HYB_TTDQ:
    case KIND_HYB_SQW:
        hyb_update(self, k, i_alpha, i_beta, u_alpha, u_beta, running);
        break;
    default:
        sens_update(e, i_alpha, i_beta, th_e, w_e);
    }
}

/* _PllTracker / _LuenbergerTracker: w_smooth and sync */
static double tracker_w_smooth(Core *self)
{
    return self->hyb.hf_kind == KIND_TTDQ ? self->rot.pll.w_i : self->sqw.obs.w_hat;
}

static void tracker_sync(Core *self, double theta, double w, double accel, double torque)
{
    HYB *h = &self->hyb;
    if (h->hf_kind == KIND_TTDQ) {
        PLL *p = &self->rot.pll; /* pll.reset(theta + T_s w, w) */
        p->theta_hat = py_mod(theta + h->tr_T_s * w, TWO_PI);
        p->w_hat = w;
        p->w_i = w;
    } else {
        LUEN *o = &self->sqw.obs; /* obs.reset(theta, w, accel + k_x torque) */
        o->theta_hat = py_mod(theta, TWO_PI);
        o->w_hat = w;
        o->x = accel + h->tr_k_x * torque;
    }
}

/* HybridEstimator.update */
static void hyb_update(Core *self, long long k, double i_alpha, double i_beta,
                       double u_alpha, double u_beta, int running)
{
    HYB *h = &self->hyb;
    EST *hf = &h->hf;
    FLUX *obs = &h->obs;
    EST *e = &self->est;
    est_update(self, h->hf_kind, hf, k, i_alpha, i_beta, 0.0, 0.0, u_alpha, u_beta, running);
    double lam = h->weight;
    double th, w, w_s, err;
    if (lam == 0.0) {
        w_s = tracker_w_smooth(self);
        th = hf->theta_hat;
        flux_update_slaved(obs, i_alpha, i_beta, u_alpha, u_beta, th, w_s);
        w = hf->w_hat;
        err = hf->err;
    } else {
        flux_update(obs, i_alpha, i_beta, u_alpha, u_beta);
        double w_o = obs->w_hat;
        if (lam == 1.0) {
            th = obs->theta_hat;
            w = w_o;
            w_s = w_o;
            err = obs->eps;
            tracker_sync(self, th, w_o, obs->accel, self->tau_ref);
        } else {
            double th_h = hf->theta_hat;
            double d = py_mod(obs->theta_hat - th_h + M_PI, TWO_PI) - M_PI;
            th = py_mod(th_h + lam * d, TWO_PI);
            double w_h = hf->w_hat;
            w = w_h + lam * (w_o - w_h);
            double w_t = tracker_w_smooth(self);
            w_s = w_t + lam * (w_o - w_t);
            double e_h = hf->err;
            err = e_h + lam * (obs->eps - e_h);
        }
    }
    e->theta_hat = th;
    e->w_hat = w;
    e->err = err;
    double g = h->gain;
    if (g == 1.0) {
        e->i_alpha_f = hf->i_alpha_f;
        e->i_beta_f = hf->i_beta_f;
    } else if (g == 0.0) {
        e->i_alpha_f = i_alpha;
        e->i_beta_f = i_beta;
    } else {
        e->i_alpha_f = i_alpha + g * (hf->i_alpha_f - i_alpha);
        e->i_beta_f = i_beta + g * (hf->i_beta_f - i_beta);
    }
    double y = running ? band_play(&h->band, h->y, w_s) : 0.0;
    h->y = y;
    band_weights(&h->band, y, &h->weight, &h->gain);
}

static void est_injection(Core *self, int kind, double *u_a, double *u_b)
{
    if (kind == KIND_HYB_TTDQ || kind == KIND_HYB_SQW) {
        double g = self->hyb.gain;
        if (g == 0.0) {
            *u_a = 0.0;
            *u_b = 0.0;
            return;
        }
        est_injection(self, self->hyb.hf_kind, u_a, u_b);
        if (g != 1.0) {
            *u_a = g * *u_a;
            *u_b = g * *u_b;
        }
    } else if (kind == KIND_SQW) {
        *u_a = self->sqw.u_next_a;
        *u_b = self->sqw.u_next_b;
    } else if (self->kind == KIND_SENSORED) {
        *u_a = 0.0;
        *u_b = 0.0;
    } else {
        rot_injection(&self->rot, u_a, u_b);
    }
}

/* step(meas): Controller.step, or None (nothing changed) for a period Python runs */
static PyObject *Core_step(Core *self, PyObject *meas)
{
    long long mode = self->mode;
    EST *e = &self->est;
    if (mode == MODE_DISABLED) {
        PyObject *k = meas_field(self, meas, 0);
        if (k == NULL)
            return NULL;
        PyObject *out = make_output(self, k, 0.5, 0.5, 0.5, 0, py_mod(e->theta_hat, TWO_PI),
                                    e->w_hat, 0.0, mode, 0.0, 0.0);
        Py_DECREF(k);
        return out;
    }
    if (mode != MODE_RUN && mode != MODE_ALIGN)
        Py_RETURN_NONE;
    if (mode == MODE_ALIGN
        && (self->settled ? self->n_mode + 1 >= self->n_settle : self->n_mode + 1 >= self->n_align))
        Py_RETURN_NONE; /* the alignment ends in this period */
    if ((self->kind == KIND_SQW || self->kind == KIND_HYB_SQW) && sqw_needs_python(&self->sqw))
        Py_RETURN_NONE;
    double i_a, i_b, i_c, u_dc, th_e = 0.0, w_e_true = 0.0;
    if (meas_double(self, meas, 1, &i_a) < 0 || meas_double(self, meas, 2, &i_b) < 0
        || meas_double(self, meas, 3, &i_c) < 0 || meas_double(self, meas, 4, &u_dc) < 0)
        return NULL;
    if (self->kind == KIND_SENSORED) {
        /* the sensored baseline only; a missing truth is Python's error to raise */
        PyObject *t = meas_field(self, meas, 5), *w = meas_field(self, meas, 6);
        int missing = t == NULL || w == NULL || t == Py_None || w == Py_None;
        if (!missing) {
            th_e = PyFloat_AsDouble(t);
            w_e_true = PyFloat_AsDouble(w);
        }
        Py_XDECREF(t);
        Py_XDECREF(w);
        if (PyErr_Occurred())
            return NULL;
        if (missing)
            Py_RETURN_NONE;
    }
    if (u_dc == 0.0)
        Py_RETURN_NONE; /* Python raises its ZeroDivisionError */
    PyObject *k_obj = meas_field(self, meas, 0);
    if (k_obj == NULL)
        return NULL;
    long long k = PyLong_AsLongLong(k_obj);
    if (k == -1 && PyErr_Occurred()) {
        Py_DECREF(k_obj);
        return NULL;
    }

    double i_alpha = (2.0 * i_a - i_b - i_c) / 3.0;
    double i_beta = (i_b - i_c) * SQRT3_INV;
    est_update(self, self->kind, e, k, i_alpha, i_beta, th_e, w_e_true, self->u_a2, self->u_b2,
               mode == MODE_RUN);
    double th = e->theta_hat;
    double w = e->w_hat;
    double c = cos(th);
    double s = sin(th);
    double i_af = e->i_alpha_f;
    double i_bf = e->i_beta_f;
    double i_d = c * i_af + s * i_bf;
    double i_q = c * i_bf - s * i_af;
    double i_d_pi, i_q_pi;
    if (self->raw_feedback) {
        i_d_pi = c * i_alpha + s * i_beta;
        i_q_pi = c * i_beta - s * i_alpha;
    } else {
        i_d_pi = i_d;
        i_q_pi = i_q;
    }
    double w_m = fo_update(&self->lpf_w, w / self->n_p);
    self->w_m_hat = w_m;
    double i_d_ref, i_q_ref, tau;
    if (mode == MODE_RUN && self->has_i_ref) {
        i_d_ref = self->i_ref_d;
        i_q_ref = self->i_ref_q;
        tau = self->k_tau * i_q_ref;
    } else if (mode == MODE_RUN) {
        double tau_u = pi_output(&self->pi_w, self->w_m_ref, w_m, 0.0);
        double tau_max = self->tau_max;
        tau = tau_u > tau_max ? tau_max : (tau_u < -tau_max ? -tau_max : tau_u);
        i_d_ref = 0.0;
        i_q_ref = tau / self->k_tau;
        double r2 = self->i_max * self->i_max - i_d_ref * i_d_ref;
        double i_q_max = sqrt(0.0 > r2 ? 0.0 : r2);
        if (i_q_ref > i_q_max)
            i_q_ref = i_q_max;
        else if (i_q_ref < -i_q_max)
            i_q_ref = -i_q_max;
        tau = self->k_tau * i_q_ref;
    } else {
        i_d_ref = i_q_ref = tau = 0.0;
    }
    double w_e = self->n_p * w_m;
    double u_d = pi_output(&self->pi_d, i_d_ref, i_d_pi, -w_e * self->L_q * i_q);
    double u_q = pi_output(&self->pi_q, i_q_ref, i_q_pi, w_e * (self->L_d * i_d + self->psi_f));
    double u_ah, u_bh;
    est_injection(self, self->kind, &u_ah, &u_bh);
    double u_lim = u_dc * SQRT3_INV - sqrt(u_ah * u_ah + u_bh * u_bh);
    double mag2 = u_d * u_d + u_q * u_q;
    double u_dl, u_ql;
    if (mag2 > u_lim * u_lim) {
        double r = u_lim / sqrt(mag2);
        u_dl = u_d * r;
        u_ql = u_q * r;
    } else {
        u_dl = u_d;
        u_ql = u_q;
    }
    double th_u = th + self->t_delay * w;
    double c_u = cos(th_u);
    double s_u = sin(th_u);
    double u_a = c_u * u_dl - s_u * u_ql + u_ah;
    double u_b = s_u * u_dl + c_u * u_ql + u_bh;
    double dd[3];
    svpwm(u_a, u_b, u_dc, dd);
    self->u_a2 = self->u_a1;
    self->u_b2 = self->u_b1;
    self->u_a1 = u_a;
    self->u_b1 = u_b;
    PyObject *out = make_output(self, k_obj, dd[0], dd[1], dd[2], 1, py_mod(th, TWO_PI),
                                w_m * self->n_p, e->err, mode, i_d, i_q);
    Py_DECREF(k_obj);
    pi_update(&self->pi_d, u_dl);
    pi_update(&self->pi_q, u_ql);
    self->u_d = u_dl;
    self->u_q = u_ql;
    if (mode == MODE_RUN && !self->has_i_ref)
        pi_update(&self->pi_w, tau);
    self->i_d_ref = i_d_ref;
    self->i_q_ref = i_q_ref;
    self->tau_ref = tau;
    if (mode == MODE_ALIGN)
        self->n_mode += 1; /* the hand-over itself was left to Python above */
    self->dirty = 1;
    return out;
}

/* bind(state, fallback): run() keeps the states of the controller whose __dict__ is state */
static PyObject *Core_bind(Core *self, PyObject *args)
{
    PyObject *state, *fallback;
    if (!PyArg_ParseTuple(args, "O!O", &PyDict_Type, &state, &fallback))
        return NULL;
    Py_INCREF(state);
    Py_XSETREF(self->state, state);
    Py_INCREF(fallback);
    Py_XSETREF(self->fallback, fallback);
    self->holds = 0;
    Py_RETURN_NONE;
}

/* run(meas): the controller's step: load the states if Python holds them, step in C, or
 * hand the states and the period over to the Python step (fallback) */
static PyObject *Core_run(Core *self, PyObject *meas)
{
    if (self->state == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "compiled controller: run() before bind()");
        return NULL;
    }
    if (!self->holds) {
        PyObject *r = Core_load(self, self->state);
        if (r == NULL)
            return NULL;
        Py_DECREF(r);
        self->holds = 1;
    }
    PyObject *out = Core_step(self, meas);
    if (out != Py_None)
        return out;
    Py_DECREF(out);
    if (self->dirty) {
        PyObject *r = Core_store(self, self->state);
        if (r == NULL)
            return NULL;
        Py_DECREF(r);
    }
    self->holds = 0;
    return PyObject_CallOneArg(self->fallback, meas);
}

static PyObject *Core_get_dirty(Core *self, void *closure)
{
    return PyBool_FromLong(self->dirty);
}

static PyObject *Core_get_holds(Core *self, void *closure)
{
    return PyBool_FromLong(self->holds);
}

static int Core_set_holds(Core *self, PyObject *v, void *closure)
{
    int t = v == NULL ? 0 : PyObject_IsTrue(v);
    if (t < 0)
        return -1;
    self->holds = t;
    return 0;
}

static PyMethodDef Core_methods[] = {
    {"load", (PyCFunction)Core_load, METH_O,
     "Read every constant and state from the controller's __dict__ and its objects."},
    {"store", (PyCFunction)Core_store, METH_O,
     "Write the states back into the controller's __dict__ and its objects."},
    {"step", (PyCFunction)Core_step, METH_O,
     "Controller.step(meas) compiled, or None for a period the Python step must run."},
    {"bind", (PyCFunction)Core_bind, METH_VARARGS,
     "bind(state, fallback): the controller's __dict__ and its Python step, for run()."},
    {"run", (PyCFunction)Core_run, METH_O,
     "The controller's step: compiled, or the Python step on the same states."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Core_getset[] = {
    {"dirty", (getter)Core_get_dirty, NULL, "stepped since the last load() or store()", NULL},
    {"holds", (getter)Core_get_holds, (setter)Core_set_holds,
     "the core holds the states (False: Python does; run() loads them first)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyTypeObject CoreType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "controller._cctl.Core",
    .tp_basicsize = sizeof(Core),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "The compiled controller step (controller._engine).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Core_init,
    .tp_dealloc = (destructor)Core_dealloc,
    .tp_traverse = (traverseproc)Core_traverse,
    .tp_clear = (inquiry)Core_clear,
    .tp_methods = Core_methods,
    .tp_getset = Core_getset,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "controller._cctl",
    "The compiled controller step (see controller._engine).", -1, NULL,
};

PyMODINIT_FUNC PyInit__cctl(void)
{
    TWO_PI = 2.0 * M_PI;
    SQRT3_INV = 1.0 / sqrt(3.0);
    SQRT3_HALF = 0.5 * sqrt(3.0);
    if (PyType_Ready(&CoreType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&CoreType);
    if (PyModule_AddObject(m, "Core", (PyObject *)&CoreType) < 0) {
        Py_DECREF(&CoreType);
        Py_DECREF(m);
        return NULL;
    }
    PyModule_AddIntConstant(m, "KIND_TTDQ", KIND_TTDQ);
    PyModule_AddIntConstant(m, "KIND_TTAB", KIND_TTAB);
    PyModule_AddIntConstant(m, "KIND_SFHF", KIND_SFHF);
    PyModule_AddIntConstant(m, "KIND_SQW", KIND_SQW);
    PyModule_AddIntConstant(m, "KIND_SENSORED", KIND_SENSORED);
    PyModule_AddIntConstant(m, "KIND_HYB_TTDQ", KIND_HYB_TTDQ);
    PyModule_AddIntConstant(m, "KIND_HYB_SQW", KIND_HYB_SQW);
    return m;
}
