/* The CPython binding of the controller core (controller/core/): no arithmetic here.
 *
 * A Core object holds one cc_foc_t (the controller, its estimator and start-up).
 * Python designs every gain and filter (controller/_controller.py and the
 * estimators' modules) and hands the values by position (controller/_compiled.py) to
 * the design methods below, each of which calls its one cc_design_* function
 * (core/cc_design.h, the design's mapping onto the core's _init calls, which the header
 * `bench codegen --estimator` writes for a firmware calls too); the core then runs every
 * period, commands included, and keeps every state.  The seam's records cross as structs: a
 * Measurement's slots are read, and a ControlOutput's filled, in the order of
 * their dataclass fields (the type's member table), never by attribute name.
 * The states Python may read are the Core's members (offsets into the C struct).
 *
 * A user's Python estimator (controller.Estimator) runs in the core as an external
 * estimator (CC_EST_EXTERNAL, cc_estimator.h): the functions below adapt the Python
 * object to the interface's function pointers.  The core calls them from its step, with
 * the GIL held (the step is a Python call); each calls the object's method as the Python
 * step does, and reads what it publishes by the protocol's attribute names.  An exception
 * the estimator raises is left set, the core stops the period there (CC_ERR_ESTIMATOR),
 * and the step raises that same exception, as the Python step does.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stddef.h>
#include <stdint.h>
#include <structmember.h>

#include "core/cc_compensation.h"
#include "core/cc_design.h"
#include "core/cc_foc.h"
#include "core/cc_flux_observer.h"
#include "core/cc_hybrid.h"
#include "core/cc_pi.h"
#include "core/cc_pll.h"
#include "core/cc_startup.h"
#include "core/cc_supervision.h"
#include "core/cc_svpwm.h"

#define N_MEAS 7 /* k, i_a, i_b, i_c, u_dc, theta_e, w_e */
#define N_OUT 11 /* k, d_a, d_b, d_c, enable, theta_hat, w_hat, err, mode, i_d, i_q */
/* EstimatorInput: k, i_alpha, i_beta, torque, theta_e, w_e, u_alpha, u_beta, running,
 * accel_ref */
#define N_IN 10

typedef struct {
    PyObject_HEAD
    cc_foc_t c;
    cc_sup_t sup; /* the supervision after the step, when sup_on */
    int sup_on;
    PyTypeObject *meas_t, *out_t;
    Py_ssize_t meas_off[N_MEAS], out_off[N_OUT];
    /* an external estimator: the Python object, EstimatorInput and its slots, and the
     * measurement of the step in progress (its k, theta_e and w_e are handed on as the
     * Python step hands them) */
    PyObject *est;
    int calls_python; /* the external estimator is a Python object (else functions in C) */
    PyTypeObject *in_t;
    Py_ssize_t in_off[N_IN];
    PyObject *meas;
} Core;

/* the offsets of the slots a tuple of member descriptors names, in its order (Python
 * hands the descriptors of a slotted dataclass in the order of its fields) */
static int slot_offsets(PyTypeObject *tp, PyObject *descr, Py_ssize_t *off, int n,
                        const char *what)
{
    if (!PyTuple_Check(descr) || PyTuple_GET_SIZE(descr) != n)
        goto bad;
    for (int j = 0; j < n; j++) {
        PyObject *d = PyTuple_GET_ITEM(descr, j);
        if (!Py_IS_TYPE(d, &PyMemberDescr_Type) || PyDescr_TYPE(d) != tp)
            goto bad;
        PyMemberDef *m = ((PyMemberDescrObject *)d)->d_member;
        if (m->type != T_OBJECT_EX || (m->flags & READONLY))
            goto bad;
        off[j] = m->offset;
    }
    return 0;
bad:
    PyErr_Format(PyExc_TypeError,
                 "compiled controller: %s needs the %d slot descriptors of its fields, in order",
                 what, n);
    return -1;
}

static int Core_traverse(Core *self, visitproc visit, void *arg)
{
    Py_VISIT(self->meas_t);
    Py_VISIT(self->out_t);
    Py_VISIT(self->est);
    Py_VISIT(self->in_t);
    return 0;
}

static int Core_clear(Core *self)
{
    Py_CLEAR(self->meas_t);
    Py_CLEAR(self->out_t);
    Py_CLEAR(self->est);
    Py_CLEAR(self->in_t);
    return 0;
}

static void Core_dealloc(Core *self)
{
    PyObject_GC_UnTrack(self);
    Core_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Core(kind, Measurement, its fields' slot descriptors, ControlOutput, its) */
static int Core_init(Core *self, PyObject *args, PyObject *kwds)
{
    int kind;
    PyObject *mt, *ot, *md, *od;
    (void)kwds;
    if (!PyArg_ParseTuple(args, "iO!OO!O", &kind, &PyType_Type, &mt, &md, &PyType_Type, &ot,
                          &od))
        return -1;
    self->sup_on = 0;
    if (cc_design_init(&self->c, &self->sup, kind) < 0) {
        PyErr_Format(PyExc_ValueError, "compiled controller: unknown estimator kind %d", kind);
        return -1;
    }
    if (slot_offsets((PyTypeObject *)mt, md, self->meas_off, N_MEAS, "the measurement") < 0
        || slot_offsets((PyTypeObject *)ot, od, self->out_off, N_OUT, "the output") < 0)
        return -1;
    Py_INCREF(mt);
    Py_XSETREF(self->meas_t, (PyTypeObject *)mt);
    Py_INCREF(ot);
    Py_XSETREF(self->out_t, (PyTypeObject *)ot);
    return 0;
}

/* ---------------------------------------------------------------- design values */
/* Each design method converts Python's values and calls its cc_design_* function
 * (core/cc_design.h: the one mapping onto the core's _init calls, which the firmware's
 * generated header calls too); tuples cross as arrays of doubles, None as NULL. */
static PyObject *Core_foc(Core *self, PyObject *args)
{
    double n_p, L_d, L_q, psi_f, i_max, tau_max, t_delay, theta0;
    long long n_align, n_settle;
    int raw, align;
    if (!PyArg_ParseTuple(args, "dddddddLLdpp", &n_p, &L_d, &L_q, &psi_f, &i_max, &tau_max,
                          &t_delay, &n_align, &n_settle, &theta0, &raw, &align))
        return NULL;
    cc_design_foc(&self->c, n_p, L_d, L_q, psi_f, i_max, tau_max, t_delay, n_align, n_settle,
                  theta0, raw, align);
    Py_RETURN_NONE;
}

static PyObject *Core_pi(Core *self, PyObject *args)
{
    int which;
    double k_p, k_i, T_s, k_t;
    if (!PyArg_ParseTuple(args, "idddd", &which, &k_p, &k_i, &T_s, &k_t))
        return NULL;
    cc_design_pi(&self->c, which, k_p, k_i, T_s, k_t);
    Py_RETURN_NONE;
}

static PyObject *Core_speed_filter(Core *self, PyObject *args)
{
    double b0, b1, a1;
    if (!PyArg_ParseTuple(args, "ddd", &b0, &b1, &a1))
        return NULL;
    cc_design_speed_filter(&self->c, b0, b1, a1);
    Py_RETURN_NONE;
}

static PyObject *Core_polarity(Core *self, PyObject *args)
{
    double L_d, T_s, i_pulse, u_frac;
    if (!PyArg_ParseTuple(args, "dddd", &L_d, &T_s, &i_pulse, &u_frac))
        return NULL;
    cc_design_polarity(&self->c, L_d, T_s, i_pulse, u_frac);
    Py_RETURN_NONE;
}

/* rotating(V_h, wT, inv_norm, (pll k_p, k_i, T_s), (bpf b0, b1, b2, a1, a2), (lpf b0, b1, a1),
 *          (hpf b0, b1, a1) or None, (tracking w_h, T_s, B, w0_min) or None
 *          [, (quadrature twin b0, b1, b2, a1, a2) or None]) */
static PyObject *Core_rotating(Core *self, PyObject *args)
{
    double V_h, wT, inv_norm, pll[3], bpf[5], lpf[3], hpf[3], track[4], quad[5];
    PyObject *hpf_o, *track_o, *quad_o = Py_None;
    if (!PyArg_ParseTuple(args, "ddd(ddd)(ddddd)(ddd)OO|O", &V_h, &wT, &inv_norm, &pll[0],
                          &pll[1], &pll[2], &bpf[0], &bpf[1], &bpf[2], &bpf[3], &bpf[4], &lpf[0],
                          &lpf[1], &lpf[2], &hpf_o, &track_o, &quad_o))
        return NULL;
    if ((hpf_o != Py_None && !PyArg_ParseTuple(hpf_o, "ddd", &hpf[0], &hpf[1], &hpf[2]))
        || (track_o != Py_None
            && !PyArg_ParseTuple(track_o, "dddd", &track[0], &track[1], &track[2], &track[3]))
        || (quad_o != Py_None
            && !PyArg_ParseTuple(quad_o, "ddddd", &quad[0], &quad[1], &quad[2], &quad[3],
                                 &quad[4])))
        return NULL;
    cc_design_rotating(&self->c, V_h, wT, inv_norm, pll, bpf, lpf,
                       hpf_o != Py_None ? hpf : NULL, track_o != Py_None ? track : NULL,
                       quad_o != Py_None ? quad : NULL);
    Py_RETURN_NONE;
}

/* square_wave(cic, M, U_h, t_comp, k_err, (observer T_s, g1, g2, g3, gt)) */
static PyObject *Core_square_wave(Core *self, PyObject *args)
{
    int cic;
    long long M;
    double U_h, t_comp, k_err, obs[5];
    if (!PyArg_ParseTuple(args, "pLddd(ddddd)", &cic, &M, &U_h, &t_comp, &k_err, &obs[0],
                          &obs[1], &obs[2], &obs[3], &obs[4]))
        return NULL;
    if (cc_design_square_wave(&self->c, cic, M, U_h, t_comp, k_err, obs) < 0) {
        PyErr_Format(PyExc_ValueError, "compiled controller: CIC delay %lld outside 1..%d", M,
                     CC_CIC_MAX);
        return NULL;
    }
    Py_RETURN_NONE;
}

/* hybrid((R_s, L_d, L_q, psi_f, T_s, zeta_f, w_min, k_p, k_i), (w_lo, w_mid, w_hi, h),
 *        T_s, n_p, J) */
static PyObject *Core_hybrid(Core *self, PyObject *args)
{
    double obs[9], band[4], T_s, n_p, J;
    if (!PyArg_ParseTuple(args, "(ddddddddd)(dddd)ddd", &obs[0], &obs[1], &obs[2], &obs[3],
                          &obs[4], &obs[5], &obs[6], &obs[7], &obs[8], &band[0], &band[1],
                          &band[2], &band[3], &T_s, &n_p, &J))
        return NULL;
    cc_design_hybrid(&self->c, obs, band, T_s, n_p, J);
    Py_RETURN_NONE;
}

/* supervision(T_s, i_rail, n_range, i_res, du_stuck, n_stuck, i_min, rho_open, n_open_min,
 *             n_open_max, u_uv, u_ov, u_hyst, n_dc): Supervisor.args() */
static PyObject *Core_supervision(Core *self, PyObject *args)
{
    double T_s, i_rail, i_res, du_stuck, i_min, rho_open, u_uv, u_ov, u_hyst;
    long long n_range, n_stuck, n_open_min, n_open_max, n_dc;
    if (!PyArg_ParseTuple(args, "ddLddLddLLdddL", &T_s, &i_rail, &n_range, &i_res, &du_stuck,
                          &n_stuck, &i_min, &rho_open, &n_open_min, &n_open_max, &u_uv, &u_ov,
                          &u_hyst, &n_dc))
        return NULL;
    cc_design_supervision(&self->sup, T_s, i_rail, n_range, i_res, du_stuck, n_stuck, i_min,
                          rho_open, n_open_min, n_open_max, u_uv, u_ov, u_hyst, n_dc);
    self->sup_on = 1;
    Py_RETURN_NONE;
}

/* the addresses of the core's cc_foc_t and cc_sup_t (NULL: no supervision), for a caller
 * that runs the periods in C on this same core (bench/nodes/native/bn_ctl.h) */
static PyObject *Core_address(Core *self, PyObject *Py_UNUSED(ignored))
{
    return Py_BuildValue("(KK)", (unsigned long long)(uintptr_t)&self->c,
                         (unsigned long long)(self->sup_on ? (uintptr_t)&self->sup : 0));
}

/* compensation((T_s, t_dead, v_ce, v_f, i_band, sine, hf_next) or None, (k_dq, sal_own) or
 *              None, offset periods or None, (I_p, I_n) or None): the countermeasures
 *              switched on, and the rotating injection's model HF amplitudes */
static PyObject *Core_compensation(Core *self, PyObject *args)
{
    PyObject *dt_o, *cross_o, *cal_o, *hf_o;
    double dt[7], cross[2], hf[2];
    long long n = 0;
    if (!PyArg_ParseTuple(args, "OOOO", &dt_o, &cross_o, &cal_o, &hf_o))
        return NULL;
    if (dt_o != Py_None) {
        int sine, hf_next;
        if (!PyArg_ParseTuple(dt_o, "dddddpp", &dt[0], &dt[1], &dt[2], &dt[3], &dt[4], &sine,
                              &hf_next))
            return NULL;
        dt[5] = sine ? 1.0 : 0.0;
        dt[6] = hf_next ? 1.0 : 0.0;
    }
    if (cross_o != Py_None) {
        int sal_own;
        if (!PyArg_ParseTuple(cross_o, "dp", &cross[0], &sal_own))
            return NULL;
        cross[1] = sal_own ? 1.0 : 0.0;
    }
    if (cal_o != Py_None) {
        n = PyLong_AsLongLong(cal_o);
        if (n == -1 && PyErr_Occurred())
            return NULL;
    }
    if (hf_o != Py_None && !PyArg_ParseTuple(hf_o, "dd", &hf[0], &hf[1]))
        return NULL;
    if (cc_design_compensation(&self->c, dt_o != Py_None ? dt : NULL,
                               cross_o != Py_None ? cross : NULL, cal_o != Py_None ? &n : NULL,
                               hf_o != Py_None ? hf : NULL)
        < 0) {
        PyErr_Format(PyExc_ValueError, "compiled controller: %lld offset periods", n);
        return NULL;
    }
    Py_RETURN_NONE;
}

/* ---------------------------------------------------------------- external estimator */
static PyObject *s_update, *s_injection, *s_reset, *s_hf_current_next, *s_saliency_offset;
static PyObject *s_pub[5]; /* theta_hat, w_hat, err, i_alpha_f, i_beta_f */

/* what the estimator publishes, read after update and reset as the Python step reads it */
static int ext_read(Core *self, cc_est_t *out)
{
    double v[5];
    for (int j = 0; j < 5; j++) {
        PyObject *a = PyObject_GetAttr(self->est, s_pub[j]);
        if (a == NULL)
            return -1;
        v[j] = PyFloat_AsDouble(a);
        Py_DECREF(a);
        if (v[j] == -1.0 && PyErr_Occurred())
            return -1;
    }
    out->theta_hat = v[0];
    out->w_hat = v[1];
    out->err = v[2];
    out->i_alpha_f = v[3];
    out->i_beta_f = v[4];
    return 0;
}

/* a pair (alpha, beta) a method returns, as the Python step unpacks it */
static int ext_pair(PyObject *r, double *a, double *b)
{
    if (r == NULL)
        return -1;
    PyObject *seq = PySequence_Fast(r, "an estimator's pair (alpha, beta)");
    Py_DECREF(r);
    if (seq == NULL)
        return -1;
    int rc = -1;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    if (n > 2) { /* Python's own words for the unpacking */
        PyErr_SetString(PyExc_ValueError, "too many values to unpack (expected 2)");
    } else if (n < 2) {
        PyErr_Format(PyExc_ValueError, "not enough values to unpack (expected 2, got %zd)", n);
    } else {
        *a = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, 0));
        if (!(*a == -1.0 && PyErr_Occurred())) {
            *b = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, 1));
            rc = (*b == -1.0 && PyErr_Occurred()) ? -1 : 0;
        }
    }
    Py_DECREF(seq);
    return rc;
}

static int ext_update(void *ctx, const cc_est_in_t *x, cc_est_t *out)
{
    Core *self = ctx;
    PyObject *m = self->meas;
    PyObject *v[N_IN];
    /* k, theta_e, w_e: the measurement's own objects */
    v[0] = *(PyObject **)((char *)m + self->meas_off[0]);
    v[4] = *(PyObject **)((char *)m + self->meas_off[5]);
    v[5] = *(PyObject **)((char *)m + self->meas_off[6]);
    if (v[0] == NULL || v[4] == NULL || v[5] == NULL) {
        PyErr_SetString(PyExc_AttributeError, "compiled controller: an unset measurement slot");
        return -1;
    }
    Py_INCREF(v[0]);
    Py_INCREF(v[4]);
    Py_INCREF(v[5]);
    v[1] = PyFloat_FromDouble(x->i_alpha);
    v[2] = PyFloat_FromDouble(x->i_beta);
    v[3] = PyFloat_FromDouble(x->torque);
    v[6] = PyFloat_FromDouble(x->u_alpha);
    v[7] = PyFloat_FromDouble(x->u_beta);
    v[8] = PyBool_FromLong(x->running);
    v[9] = PyFloat_FromDouble(x->accel_ref);
    int ok = 1;
    for (int j = 0; j < N_IN; j++)
        ok = ok && v[j] != NULL;
    PyObject *in = ok ? self->in_t->tp_alloc(self->in_t, 0) : NULL;
    if (in != NULL) { /* a frozen slotted dataclass: its slots as its __init__ fills them */
        for (int j = 0; j < N_IN; j++) {
            *(PyObject **)((char *)in + self->in_off[j]) = v[j];
            v[j] = NULL;
        }
    }
    for (int j = 0; j < N_IN; j++)
        Py_XDECREF(v[j]);
    if (in == NULL)
        return -1;
    PyObject *r = PyObject_CallMethodOneArg(self->est, s_update, in);
    Py_DECREF(in);
    if (r == NULL)
        return -1;
    Py_DECREF(r);
    return ext_read(self, out);
}

static int ext_injection(void *ctx, double *u_a, double *u_b)
{
    Core *self = ctx;
    return ext_pair(PyObject_CallMethodNoArgs(self->est, s_injection), u_a, u_b);
}

static int ext_hf_current_next(void *ctx, double *i_a, double *i_b)
{
    Core *self = ctx;
    return ext_pair(PyObject_CallMethodNoArgs(self->est, s_hf_current_next), i_a, i_b);
}

static int ext_reset(void *ctx, double theta0, cc_est_t *out)
{
    Core *self = ctx;
    PyObject *th = PyFloat_FromDouble(theta0);
    if (th == NULL)
        return -1;
    PyObject *r = PyObject_CallMethodOneArg(self->est, s_reset, th);
    Py_DECREF(th);
    if (r == NULL)
        return -1;
    Py_DECREF(r);
    return ext_read(self, out);
}

static int ext_set_saliency_offset(void *ctx, double offset)
{
    Core *self = ctx;
    PyObject *v = PyFloat_FromDouble(offset);
    if (v == NULL)
        return -1;
    int rc = PyObject_SetAttr(self->est, s_saliency_offset, v);
    Py_DECREF(v);
    return rc;
}

/* external(estimator, EstimatorInput, its fields' slot descriptors): the core's estimator
 * is this Python object (a Core of kind KIND_EXTERNAL) */
static PyObject *Core_external(Core *self, PyObject *args)
{
    PyObject *est, *it, *id;
    if (!PyArg_ParseTuple(args, "OO!O", &est, &PyType_Type, &it, &id))
        return NULL;
    if (self->c.est.kind != CC_EST_EXTERNAL) {
        PyErr_SetString(PyExc_ValueError, "compiled controller: external() on a core estimator");
        return NULL;
    }
    if (slot_offsets((PyTypeObject *)it, id, self->in_off, N_IN, "the estimator input") < 0)
        return NULL;
    Py_INCREF(est);
    Py_XSETREF(self->est, est);
    Py_INCREF(it);
    Py_XSETREF(self->in_t, (PyTypeObject *)it);
    cc_est_if_t *x = &self->c.est.ext;
    self->calls_python = 1;
    x->ctx = self;
    x->update = ext_update;
    x->injection = ext_injection;
    x->reset = ext_reset;
    x->hf_current_next = ext_hf_current_next;
    x->set_saliency_offset = ext_set_saliency_offset;
    /* what it publishes before its first update (the disabled periods report it) */
    if (ext_read(self, &self->c.est.out) < 0)
        return NULL;
    Py_RETURN_NONE;
}

/* external_c(address of a cc_est_if_t): the core's estimator is a user's estimator in C
 * (controller._cplugin.CEstimator, which keeps its library and state alive); the core
 * calls its functions directly */
static PyObject *Core_external_c(Core *self, PyObject *arg)
{
    unsigned long long addr = PyLong_AsUnsignedLongLong(arg);
    if (addr == (unsigned long long)-1 && PyErr_Occurred())
        return NULL;
    if (self->c.est.kind != CC_EST_EXTERNAL || addr == 0) {
        PyErr_SetString(PyExc_ValueError, "compiled controller: external_c() needs an external "
                                          "core and a cc_est_if_t");
        return NULL;
    }
    const cc_est_if_t *x = (const cc_est_if_t *)(uintptr_t)addr;
    if (x->update == NULL || x->injection == NULL || x->reset == NULL) {
        PyErr_SetString(PyExc_ValueError, "compiled controller: update, injection or reset is NULL");
        return NULL;
    }
    self->c.est.ext = *x;
    self->calls_python = 0;
    Py_RETURN_NONE;
}

/* the one error of a C estimator's function that returned nonzero (controller._cplugin) */
static void *c_estimator_failed(void)
{
    if (!PyErr_Occurred())
        PyErr_SetString(PyExc_RuntimeError, "the estimator in C failed: a function of its "
                                            "cc_est_if_t returned nonzero");
    return NULL;
}

/* reference_model(alpha_s, n_p, a_max, T_s): ReferenceModel's constants */
static PyObject *Core_reference_model(Core *self, PyObject *args)
{
    double alpha_s, n_p, a_max, T_s;
    if (!PyArg_ParseTuple(args, "dddd", &alpha_s, &n_p, &a_max, &T_s))
        return NULL;
    cc_design_reference_model(&self->c, alpha_s, n_p, a_max, T_s);
    Py_RETURN_NONE;
}

/* mechanical(T_s, g1, g2, g3, gt, l3): a rotating demodulator's observer = "mechanical",
 * after rotating() */
static PyObject *Core_mechanical(Core *self, PyObject *args)
{
    double T_s, g1, g2, g3, gt, l3;
    if (!PyArg_ParseTuple(args, "dddddd", &T_s, &g1, &g2, &g3, &gt, &l3))
        return NULL;
    cc_design_mechanical(&self->c, T_s, g1, g2, g3, gt, l3);
    Py_RETURN_NONE;
}

/* measured(floor): a rotating demodulator's normalise = "measured", after rotating() */
static PyObject *Core_measured(Core *self, PyObject *arg)
{
    double amp_floor = PyFloat_AsDouble(arg);
    if (amp_floor == -1.0 && PyErr_Occurred())
        return NULL;
    cc_design_measured(&self->c, amp_floor);
    Py_RETURN_NONE;
}

/* accel_ff(): tt-dq (or the hybrid's tt-dq) feeds the designed acceleration into its PLL */
static PyObject *Core_accel_ff(Core *self, PyObject *Py_UNUSED(ignored))
{
    cc_design_accel_ff(&self->c);
    Py_RETURN_NONE;
}

/* ---------------------------------------------------------------- commands */
static PyObject *Core_set_speed_ref(Core *self, PyObject *v)
{
    double w = PyFloat_AsDouble(v);
    if (w == -1.0 && PyErr_Occurred())
        return NULL;
    cc_foc_set_speed_ref(&self->c, w);
    Py_RETURN_NONE;
}

static PyObject *Core_set_current_ref(Core *self, PyObject *v)
{
    double i_d = 0.0, i_q = 0.0;
    if (v != Py_None && !PyArg_ParseTuple(v, "dd", &i_d, &i_q))
        return NULL;
    cc_foc_set_current_ref(&self->c, v != Py_None, i_d, i_q);
    Py_RETURN_NONE;
}

static PyObject *Core_set_enable(Core *self, PyObject *v)
{
    int on = PyObject_IsTrue(v);
    if (on < 0)
        return NULL;
    if (cc_foc_set_enable(&self->c, on) != CC_OK)
        return c_estimator_failed(); /* or the external estimator's exception */
    Py_RETURN_NONE;
}

static PyObject *Core_injection(Core *self, PyObject *Py_UNUSED(ignored))
{
    double u_a, u_b;
    if (cc_estim_injection(&self->c.est, &u_a, &u_b))
        return c_estimator_failed(); /* or the external estimator's exception */
    return Py_BuildValue("(dd)", u_a, u_b);
}

/* ---------------------------------------------------------------- the period */
static PyObject *slot(PyObject *o, Py_ssize_t off)
{
    PyObject *v = *(PyObject **)((char *)o + off);
    if (v == NULL)
        PyErr_SetString(PyExc_AttributeError, "compiled controller: an unset measurement slot");
    return v;
}

static int slot_d(PyObject *o, Py_ssize_t off, double *out)
{
    PyObject *v = slot(o, off);
    if (v == NULL)
        return -1;
    *out = PyFloat_AsDouble(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static PyObject *Core_step(Core *self, PyObject *meas)
{
    if (!PyObject_TypeCheck(meas, self->meas_t)) {
        PyErr_Format(PyExc_TypeError, "compiled controller: step() takes a %s, not %s",
                     self->meas_t->tp_name, Py_TYPE(meas)->tp_name);
        return NULL;
    }
    cc_meas_t m;
    PyObject *k = slot(meas, self->meas_off[0]);
    if (k == NULL)
        return NULL;
    m.k = PyLong_AsLongLong(k);
    if ((m.k == -1 && PyErr_Occurred()) || slot_d(meas, self->meas_off[1], &m.i_a) < 0
        || slot_d(meas, self->meas_off[2], &m.i_b) < 0
        || slot_d(meas, self->meas_off[3], &m.i_c) < 0
        || slot_d(meas, self->meas_off[4], &m.u_dc) < 0)
        return NULL;
    m.has_truth = 0;
    m.theta_e = m.w_e = 0.0;
    if (self->c.est.kind == CC_EST_SENSORED) { /* the truth: the sensored baseline only */
        PyObject *t = slot(meas, self->meas_off[5]), *w = slot(meas, self->meas_off[6]);
        if (t == NULL || w == NULL)
            return NULL;
        if (t != Py_None && w != Py_None) {
            if (slot_d(meas, self->meas_off[5], &m.theta_e) < 0
                || slot_d(meas, self->meas_off[6], &m.w_e) < 0)
                return NULL;
            m.has_truth = 1;
        }
    }
    cc_out_t o;
    self->meas = meas; /* borrowed for the step: an external estimator's input */
    int rc = cc_foc_step(&self->c, &m, &o);
    self->meas = NULL;
    if (rc == CC_ERR_ESTIMATOR) /* the external estimator's exception, as the Python step */
        return c_estimator_failed(); /* raises it, or a C estimator's failure */
    if (rc == CC_ERR_U_DC) {
        PyErr_SetString(PyExc_ZeroDivisionError, "float division by zero (u_dc = 0)");
        return NULL;
    }
    if (rc == CC_ERR_NO_TRUTH) {
        PyErr_SetString(PyExc_ValueError,
                        "the sensored estimator needs Measurement.theta_e and w_e");
        return NULL;
    }
    if (self->sup_on)
        cc_sup_after(&self->sup, &self->c, &m, &o);
    PyObject *v[N_OUT];
    Py_INCREF(k);
    v[0] = k; /* the measurement's own k */
    v[1] = PyFloat_FromDouble(o.d_a);
    v[2] = PyFloat_FromDouble(o.d_b);
    v[3] = PyFloat_FromDouble(o.d_c);
    v[4] = PyBool_FromLong(o.enable);
    v[5] = PyFloat_FromDouble(o.theta_hat);
    v[6] = PyFloat_FromDouble(o.w_hat);
    v[7] = PyFloat_FromDouble(o.err);
    v[8] = PyLong_FromLongLong(o.mode);
    v[9] = PyFloat_FromDouble(o.i_d);
    v[10] = PyFloat_FromDouble(o.i_q);
    int ok = 1;
    for (int j = 0; j < N_OUT; j++)
        ok = ok && v[j] != NULL;
    PyObject *out = ok ? self->out_t->tp_alloc(self->out_t, 0) : NULL;
    if (out != NULL) { /* a frozen slotted dataclass: its slots as its __init__ fills them */
        for (int j = 0; j < N_OUT; j++) {
            *(PyObject **)((char *)out + self->out_off[j]) = v[j];
            v[j] = NULL;
        }
    }
    for (int j = 0; j < N_OUT; j++)
        Py_XDECREF(v[j]);
    return out;
}

static PyMethodDef Core_methods[] = {
    {"foc", (PyCFunction)Core_foc, METH_VARARGS,
     "foc(n_p, L_d, L_q, psi_f, i_max, tau_max, t_delay, n_align, n_settle, theta0, raw, align)"},
    {"pi", (PyCFunction)Core_pi, METH_VARARGS, "pi(which: 0 d, 1 q, 2 speed, k_p, k_i, T_s, k_t)"},
    {"speed_filter", (PyCFunction)Core_speed_filter, METH_VARARGS, "speed_filter(b0, b1, a1)"},
    {"polarity", (PyCFunction)Core_polarity, METH_VARARGS, "polarity(L_d, T_s, i_pulse, u_frac)"},
    {"rotating", (PyCFunction)Core_rotating, METH_VARARGS,
     "rotating(V_h, wT, inv_norm, pll, bpf, lpf, hpf or None, tracking or None[, quad])"},
    {"square_wave", (PyCFunction)Core_square_wave, METH_VARARGS,
     "square_wave(cic, M, U_h, t_comp, k_err, (T_s, g1, g2, g3, gt))"},
    {"hybrid", (PyCFunction)Core_hybrid, METH_VARARGS,
     "hybrid(flux observer, band, T_s, n_p, J)"},
    {"compensation", (PyCFunction)Core_compensation, METH_VARARGS,
     "compensation(dead time or None, cross-saturation or None, offset periods or None, "
     "(I_p, I_n) or None)"},
    {"set_speed_ref", (PyCFunction)Core_set_speed_ref, METH_O, "mechanical speed (rad/s)"},
    {"set_current_ref", (PyCFunction)Core_set_current_ref, METH_O, "(i_d, i_q) or None"},
    {"set_enable", (PyCFunction)Core_set_enable, METH_O, "enable or disable"},
    {"step", (PyCFunction)Core_step, METH_O, "Controller.step(meas): one period"},
    {"supervision", (PyCFunction)Core_supervision, METH_VARARGS,
     "supervision(*Supervisor.args()): the supervision after each step"},
    {"address", (PyCFunction)Core_address, METH_NOARGS,
     "(address of the cc_foc_t, of the cc_sup_t or 0)"},
    {"external", (PyCFunction)Core_external, METH_VARARGS,
     "external(estimator, EstimatorInput, its slot descriptors): a Python estimator"},
    {"external_c", (PyCFunction)Core_external_c, METH_O,
     "external_c(address of a cc_est_if_t): a user's estimator in C"},
    {"reference_model", (PyCFunction)Core_reference_model, METH_VARARGS,
     "reference_model(alpha_s, n_p, a_max, T_s): the speed loop's designed response"},
    {"mechanical", (PyCFunction)Core_mechanical, METH_VARARGS,
     "mechanical(T_s, g1, g2, g3, gt, l3): the mechanical observer of a rotating demodulator"},
    {"measured", (PyCFunction)Core_measured, METH_O,
     "measured(floor): a rotating demodulator's normalise = 'measured'"},
    {"accel_ff", (PyCFunction)Core_accel_ff, METH_NOARGS,
     "tt-dq's acceleration feed-forward on"},
    {"injection", (PyCFunction)Core_injection, METH_NOARGS,
     "the HF voltage (alpha, beta) (V) for the next period"},
    {NULL, NULL, 0, NULL},
};

#define M_(name, field, type) \
    {name, type, offsetof(Core, c) + offsetof(cc_foc_t, field), READONLY, NULL}
#define E_(name, field) \
    {name, T_DOUBLE, offsetof(Core, c) + offsetof(cc_foc_t, est.out.field), READONLY, NULL}
static PyMemberDef Core_members[] = {
    {"kind", T_INT, offsetof(Core, c) + offsetof(cc_foc_t, est.kind), READONLY, NULL},
    {"calls_python", T_INT, offsetof(Core, calls_python), READONLY, NULL},
    M_("mode", mode, T_LONGLONG),
    M_("w_m_ref", w_m_ref, T_DOUBLE),
    M_("w_m_hat", w_m_hat, T_DOUBLE),
    M_("i_d_ref", i_d_ref, T_DOUBLE),
    M_("i_q_ref", i_q_ref, T_DOUBLE),
    M_("tau_ref", tau_ref, T_DOUBLE),
    M_("u_d", u_d, T_DOUBLE),
    M_("u_q", u_q, T_DOUBLE),
    M_("pi_d_u_i", pi_d.u_i, T_DOUBLE),
    M_("pi_q_u_i", pi_q.u_i, T_DOUBLE),
    M_("pi_w_u_i", pi_w.u_i, T_DOUBLE),
    M_("polarity_flip", polarity.flip, T_INT),
    E_("theta_hat", theta_hat),
    E_("w_hat", w_hat),
    E_("err", err),
    M_("weight", est.hyb.weight, T_DOUBLE),
    M_("gain", est.hyb.gain, T_DOUBLE),
    M_("y", est.hyb.y, T_DOUBLE),
    M_("hf_theta_hat", est.hyb.hf.theta_hat, T_DOUBLE),
    M_("hf_w_hat", est.hyb.hf.w_hat, T_DOUBLE),
    M_("obs_theta_hat", est.hyb.obs.theta_hat, T_DOUBLE),
    M_("obs_w_hat", est.hyb.obs.w_hat, T_DOUBLE),
    M_("e_alpha", est.sqw.e_alpha, T_DOUBLE),
    M_("e_beta", est.sqw.e_beta, T_DOUBLE),
    {"sup_latched", T_LONGLONG, offsetof(Core, sup.latched), READONLY, NULL},
    {"sup_detected_k", T_LONGLONG, offsetof(Core, sup.detected_k), READONLY, NULL},
    {NULL, 0, 0, 0, NULL},
};
#undef M_
#undef E_

static PyTypeObject CoreType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "controller._cctl.Core",
    .tp_basicsize = sizeof(Core),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "The controller core (controller/core/) bound to Python (controller._compiled).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Core_init,
    .tp_dealloc = (destructor)Core_dealloc,
    .tp_traverse = (traverseproc)Core_traverse,
    .tp_clear = (inquiry)Core_clear,
    .tp_methods = Core_methods,
    .tp_members = Core_members,
};

/* ---------------------------------------------------------------- the public blocks */
/* The blocks a user may call per period (controller/__init__.py; a plug-in's estimator
 * composes them): each a small type holding one core struct, whose methods call the
 * core's _init/_step/_reset and whose members are the struct's fields (design values
 * read-only, states writable).  The Python classes (controller/_pi.py, ...) subclass
 * these types and keep the design, the docstrings and the argument checks. */

/* The doubles of a fast call into v: n positional arguments, then the keywords kw (as
 * the Python signature names[] allows), at least lo and at most hi of them (v's defaults
 * stay for the rest). */
static int block_args(PyObject *const *args, Py_ssize_t n, PyObject *kw,
                      const char *const *names, Py_ssize_t lo, Py_ssize_t hi, double *v,
                      const char *what)
{
    int given[8] = {0};
    Py_ssize_t nk = kw == NULL ? 0 : PyTuple_GET_SIZE(kw);
    if (n > hi) {
        PyErr_Format(PyExc_TypeError, "%s takes at most %zd arguments (%zd given)", what, hi,
                     n + nk);
        return -1;
    }
    for (Py_ssize_t j = 0; j < n + nk; j++) {
        Py_ssize_t at = j;
        if (j >= n) { /* a keyword: its position in the signature */
            PyObject *name = PyTuple_GET_ITEM(kw, j - n);
            for (at = 0; at < hi; at++)
                if (PyUnicode_CompareWithASCIIString(name, names[at]) == 0)
                    break;
            if (at == hi || given[at]) {
                PyErr_Format(PyExc_TypeError, "%s got %s keyword argument '%U'", what,
                             at == hi ? "an unexpected" : "multiple values for", name);
                return -1;
            }
        }
        given[at] = 1;
        v[at] = PyFloat_AsDouble(args[j]);
        if (v[at] == -1.0 && PyErr_Occurred())
            return -1;
    }
    for (Py_ssize_t j = 0; j < lo; j++)
        if (!given[j]) {
            PyErr_Format(PyExc_TypeError, "%s missing required argument '%s'", what, names[j]);
            return -1;
        }
    return 0;
}

/* a block's type: its object T holds the core struct s; Python's classes subclass it */
#define BLOCK_TYPE(var, name, T, doc, init, methods, members, getset)              \
    static PyTypeObject var = {                                                    \
        PyVarObject_HEAD_INIT(NULL, 0).tp_name = "controller._cctl." name,        \
        .tp_basicsize = sizeof(T), .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE, \
        .tp_doc = doc, .tp_new = PyType_GenericNew, .tp_init = (initproc)init,    \
        .tp_methods = methods, .tp_members = members, .tp_getset = getset,         \
    }

/* a member of a block's core struct ST (field s of the block's type T) */
#define BLOCK_M(name, T, ST, field, type, flags) \
    {name, type, offsetof(T, s) + offsetof(ST, field), flags, NULL}

/* -- PI (core/cc_pi.h) */
typedef struct {
    PyObject_HEAD
    cc_pi_t s;
} PiBlock;

static int Pi_init(PiBlock *self, PyObject *args, PyObject *kwds)
{
    double k_p, k_i, T_s, k_t;
    (void)kwds;
    if (!PyArg_ParseTuple(args, "dddd", &k_p, &k_i, &T_s, &k_t))
        return -1;
    cc_pi_init(&self->s, k_p, k_i, T_s, k_t);
    return 0;
}

static PyObject *Pi_output(PiBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"r", "y", "u_ff"};
    double v[3] = {0.0, 0.0, 0.0};
    if (block_args(args, n, kw, names, 2, 3, v, "output()") < 0)
        return NULL;
    return PyFloat_FromDouble(cc_pi_output(&self->s, v[0], v[1], v[2]));
}

static PyObject *Pi_update(PiBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"u_lim"};
    double v[1];
    if (block_args(args, n, kw, names, 1, 1, v, "update()") < 0)
        return NULL;
    cc_pi_update(&self->s, v[0]);
    Py_RETURN_NONE;
}

static PyObject *Pi_reset(PiBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"u_i"};
    double v[1] = {0.0};
    if (block_args(args, n, kw, names, 0, 1, v, "reset()") < 0)
        return NULL;
    cc_pi_reset(&self->s);
    self->s.u_i = v[0]; /* the integral state given (cc_pi_reset zeroes it) */
    Py_RETURN_NONE;
}

static PyMethodDef Pi_methods[] = {
    {"output", (PyCFunction)(void (*)(void))Pi_output, METH_FASTCALL | METH_KEYWORDS,
     "output($self, /, r, y, u_ff=0.0)\n--\n\n"
     "Unlimited controller output for reference ``r`` and measurement ``y`` (cc_pi_output)."},
    {"update", (PyCFunction)(void (*)(void))Pi_update, METH_FASTCALL | METH_KEYWORDS,
     "update($self, /, u_lim)\n--\n\n"
     "Advance the integrator with the realised (limited) output ``u_lim`` (cc_pi_update)."},
    {"reset", (PyCFunction)(void (*)(void))Pi_reset, METH_FASTCALL | METH_KEYWORDS,
     "reset($self, /, u_i=0.0)\n--\n\nSet the integral state (cc_pi_reset, then ``u_i``)."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Pi_members[] = {
    BLOCK_M("k_p", PiBlock, cc_pi_t, k_p, T_DOUBLE, READONLY),
    BLOCK_M("k_i", PiBlock, cc_pi_t, k_i, T_DOUBLE, READONLY),
    BLOCK_M("k_t", PiBlock, cc_pi_t, k_t, T_DOUBLE, READONLY),
    BLOCK_M("T_s", PiBlock, cc_pi_t, T_s, T_DOUBLE, READONLY),
    BLOCK_M("u_i", PiBlock, cc_pi_t, u_i, T_DOUBLE, 0),
    BLOCK_M("_e", PiBlock, cc_pi_t, e, T_DOUBLE, 0),
    BLOCK_M("_u", PiBlock, cc_pi_t, u, T_DOUBLE, 0),
    {NULL, 0, 0, 0, NULL},
};

BLOCK_TYPE(PiType, "Pi", PiBlock, "Pi(k_p, k_i, T_s, k_t): a cc_pi_t (controller.PIController)",
           Pi_init, Pi_methods, Pi_members, NULL);

/* -- PLL (core/cc_pll.h) */
typedef struct {
    PyObject_HEAD
    cc_pll_t s;
} PllBlock;

static int Pll_init(PllBlock *self, PyObject *args, PyObject *kwds)
{
    double k_p, k_i, T_s;
    (void)kwds;
    if (!PyArg_ParseTuple(args, "ddd", &k_p, &k_i, &T_s))
        return -1;
    cc_pll_init(&self->s, k_p, k_i, T_s);
    return 0;
}

static PyObject *Pll_update(PllBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"err", "accel"};
    double v[2] = {0.0, 0.0};
    if (block_args(args, n, kw, names, 1, 2, v, "update()") < 0)
        return NULL;
    cc_pll_step(&self->s, v[0], v[1]);
    Py_RETURN_NONE;
}

static PyObject *Pll_reset(PllBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"theta0", "w0"};
    double v[2] = {0.0, 0.0};
    if (block_args(args, n, kw, names, 1, 2, v, "reset()") < 0)
        return NULL;
    cc_pll_reset(&self->s, v[0], v[1]);
    Py_RETURN_NONE;
}

static PyMethodDef Pll_methods[] = {
    {"update", (PyCFunction)(void (*)(void))Pll_update, METH_FASTCALL | METH_KEYWORDS,
     "update($self, /, err, accel=0.0)\n--\n\n"
     "Take the error of sample ``k``; advance ``theta_hat`` to ``(k+1) T_s`` (cc_pll_step).\n\n"
     "``accel`` (rad/s^2): a known acceleration fed forward into the integral, so\n"
     "that the speed follows it without the error ``accel / w_o^2`` the loop\n"
     "needs otherwise. It is an input beside the loop, not in it: the transfer\n"
     "function from ``err`` to the angle (:func:`open_loop`) stays what it is."},
    {"reset", (PyCFunction)(void (*)(void))Pll_reset, METH_FASTCALL | METH_KEYWORDS,
     "reset($self, /, theta0, w0=0.0)\n--\n\n"
     "Restart at angle ``theta0`` (rad) and speed ``w0`` (rad/s) (cc_pll_reset)."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Pll_members[] = {
    BLOCK_M("k_p", PllBlock, cc_pll_t, k_p, T_DOUBLE, READONLY),
    BLOCK_M("k_i", PllBlock, cc_pll_t, k_i, T_DOUBLE, READONLY),
    BLOCK_M("T_s", PllBlock, cc_pll_t, T_s, T_DOUBLE, READONLY),
    BLOCK_M("theta_hat", PllBlock, cc_pll_t, theta_hat, T_DOUBLE, 0),
    BLOCK_M("w_hat", PllBlock, cc_pll_t, w_hat, T_DOUBLE, 0),
    BLOCK_M("w_i", PllBlock, cc_pll_t, w_i, T_DOUBLE, 0),
    {NULL, 0, 0, 0, NULL},
};

BLOCK_TYPE(PllType, "Pll", PllBlock, "Pll(k_p, k_i, T_s): a cc_pll_t (controller.PositionObserver)",
           Pll_init, Pll_methods, Pll_members, NULL);

/* -- polarity test (core/cc_startup.h) */
typedef struct {
    PyObject_HEAD
    cc_polarity_t s;
} PolarityBlock;

static int Polarity_init(PolarityBlock *self, PyObject *args, PyObject *kwds)
{
    double L_d, T_s, i_pulse, u_frac;
    (void)kwds;
    if (!PyArg_ParseTuple(args, "dddd", &L_d, &T_s, &i_pulse, &u_frac))
        return -1;
    cc_polarity_init(&self->s, L_d, T_s, i_pulse, u_frac);
    return 0;
}

/* start(u_dc, i_d0): the Python class refuses the values for which it is undefined */
static PyObject *Polarity_start(PolarityBlock *self, PyObject *const *args, Py_ssize_t n,
                                PyObject *kw)
{
    static const char *const names[] = {"u_dc", "i_d0"};
    double v[2];
    if (block_args(args, n, kw, names, 2, 2, v, "start()") < 0)
        return NULL;
    cc_polarity_start(&self->s, v[0], v[1]);
    Py_RETURN_NONE;
}

static PyObject *Polarity_step(PolarityBlock *self, PyObject *const *args, Py_ssize_t n,
                               PyObject *kw)
{
    static const char *const names[] = {"i_d"};
    double v[1];
    if (block_args(args, n, kw, names, 1, 1, v, "step()") < 0)
        return NULL;
    return PyFloat_FromDouble(cc_polarity_step(&self->s, v[0]));
}

/* done and flip: the core's ints as Python's bools (writable: the oracle's step sets them) */
static PyObject *Polarity_get_flag(PolarityBlock *self, void *which)
{
    return PyBool_FromLong(which ? self->s.flip : self->s.done);
}

static int Polarity_set_flag(PolarityBlock *self, PyObject *v, void *which)
{
    int on = v == NULL ? -1 : PyObject_IsTrue(v);
    if (on < 0) {
        if (v == NULL)
            PyErr_SetString(PyExc_AttributeError, "cannot delete a polarity test's flag");
        return -1;
    }
    *(which ? &self->s.flip : &self->s.done) = on;
    return 0;
}

static PyGetSetDef Polarity_getset[] = {
    {"done", (getter)Polarity_get_flag, (setter)Polarity_set_flag,
     "whether the test has ended", NULL},
    {"flip", (getter)Polarity_get_flag, (setter)Polarity_set_flag,
     "whether the estimated d axis points south (flip by pi)", (void *)1},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef Polarity_methods[] = {
    {"start", (PyCFunction)(void (*)(void))Polarity_start, METH_FASTCALL | METH_KEYWORDS,
     "start($self, /, u_dc, i_d0)\n--\n\ncc_polarity_start"},
    {"step", (PyCFunction)(void (*)(void))Polarity_step, METH_FASTCALL | METH_KEYWORDS,
     "step($self, /, i_d)\n--\n\n"
     "Take the d current of sample ``k`` (A); return ``u_d`` (V) for period ``k + 1`` "
     "(cc_polarity_step)."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Polarity_members[] = {
    BLOCK_M("L_d", PolarityBlock, cc_polarity_t, L_d, T_DOUBLE, READONLY),
    BLOCK_M("T_s", PolarityBlock, cc_polarity_t, T_s, T_DOUBLE, READONLY),
    BLOCK_M("i_pulse", PolarityBlock, cc_polarity_t, i_pulse, T_DOUBLE, READONLY),
    BLOCK_M("u_frac", PolarityBlock, cc_polarity_t, u_frac, T_DOUBLE, READONLY),
    BLOCK_M("U", PolarityBlock, cc_polarity_t, U, T_DOUBLE, 0),
    BLOCK_M("N", PolarityBlock, cc_polarity_t, N, T_LONGLONG, 0),
    BLOCK_M("_n", PolarityBlock, cc_polarity_t, n, T_LONGLONG, 0),
    BLOCK_M("_i0", PolarityBlock, cc_polarity_t, i0, T_DOUBLE, 0),
    BLOCK_M("_i1", PolarityBlock, cc_polarity_t, i1, T_DOUBLE, 0),
    BLOCK_M("d_i_pos", PolarityBlock, cc_polarity_t, d_i_pos, T_DOUBLE, 0),
    BLOCK_M("d_i_neg", PolarityBlock, cc_polarity_t, d_i_neg, T_DOUBLE, 0),
    {NULL, 0, 0, 0, NULL},
};

BLOCK_TYPE(PolarityType, "Polarity", PolarityBlock,
           "Polarity(L_d, T_s, i_pulse, u_frac): a cc_polarity_t (controller.PolarityTest)",
           Polarity_init, Polarity_methods, Polarity_members, Polarity_getset);

/* -- flux observer (core/cc_flux_observer.h); R_s, zeta_f and alpha_o, which the struct
 * keeps only as derived constants, kept beside it as given */
typedef struct {
    PyObject_HEAD
    cc_flux_t s;
    double R_s, zeta_f, alpha_o;
} FluxBlock;

static int Flux_init(FluxBlock *self, PyObject *args, PyObject *kwds)
{
    double R_s, L_d, L_q, psi_f, T_s, zeta_f, w_min, k_p, k_i, alpha_o;
    (void)kwds;
    if (!PyArg_ParseTuple(args, "dddddddddd", &R_s, &L_d, &L_q, &psi_f, &T_s, &zeta_f, &w_min,
                          &k_p, &k_i, &alpha_o))
        return -1;
    cc_flux_init(&self->s, R_s, L_d, L_q, psi_f, T_s, zeta_f, w_min, k_p, k_i);
    self->R_s = R_s;
    self->zeta_f = zeta_f;
    self->alpha_o = alpha_o;
    return 0;
}

static PyObject *Flux_update(FluxBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"i_alpha", "i_beta", "u_alpha", "u_beta"};
    double v[4];
    if (block_args(args, n, kw, names, 4, 4, v, "update()") < 0)
        return NULL;
    cc_flux_step(&self->s, v[0], v[1], v[2], v[3]);
    Py_RETURN_NONE;
}

static PyObject *Flux_update_slaved(FluxBlock *self, PyObject *const *args, Py_ssize_t n,
                                    PyObject *kw)
{
    static const char *const names[] = {"i_alpha", "i_beta", "u_alpha", "u_beta", "theta", "w"};
    double v[6];
    if (block_args(args, n, kw, names, 6, 6, v, "update_slaved()") < 0)
        return NULL;
    cc_flux_step_slaved(&self->s, v[0], v[1], v[2], v[3], v[4], v[5]);
    Py_RETURN_NONE;
}

static PyObject *Flux_reset(FluxBlock *self, PyObject *const *args, Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"theta0", "w0"};
    double v[2] = {0.0, 0.0};
    if (block_args(args, n, kw, names, 1, 2, v, "reset()") < 0)
        return NULL;
    cc_flux_reset(&self->s, v[0], v[1]);
    Py_RETURN_NONE;
}

static PyObject *Flux_set_state(FluxBlock *self, PyObject *const *args, Py_ssize_t n,
                                PyObject *kw)
{
    static const char *const names[] = {"psi_alpha", "psi_beta", "i_alpha", "i_beta"};
    double v[4];
    if (block_args(args, n, kw, names, 4, 4, v, "set_state()") < 0)
        return NULL;
    cc_flux_set_state(&self->s, v[0], v[1], v[2], v[3]);
    Py_RETURN_NONE;
}

static PyMethodDef Flux_methods[] = {
    {"update", (PyCFunction)(void (*)(void))Flux_update, METH_FASTCALL | METH_KEYWORDS,
     "update($self, /, i_alpha, i_beta, u_alpha, u_beta)\n--\n\n"
     "Sensorless step: sample ``k`` (A) and the voltage of ``[(k-1) T_s, k T_s]`` (V) "
     "(cc_flux_step)."},
    {"update_slaved", (PyCFunction)(void (*)(void))Flux_update_slaved,
     METH_FASTCALL | METH_KEYWORDS,
     "update_slaved($self, /, i_alpha, i_beta, u_alpha, u_beta, theta, w)\n--\n\n"
     "Sensored step at a given angle ``theta`` (rad) and speed ``w`` (rad/s): the flux\n"
     "is corrected with ``k_1 e`` (``k_2 = 0``); the PLL state follows ``theta, w`` "
     "(cc_flux_step_slaved)."},
    {"reset", (PyCFunction)(void (*)(void))Flux_reset, METH_FASTCALL | METH_KEYWORDS,
     "reset($self, /, theta0, w0=0.0)\n--\n\n"
     "Restart at angle ``theta0`` (rad) and speed ``w0`` (rad/s); the next sample\n"
     "sets the flux estimate to the current model at that angle (cc_flux_reset)."},
    {"set_state", (PyCFunction)(void (*)(void))Flux_set_state, METH_FASTCALL | METH_KEYWORDS,
     "set_state($self, /, psi_alpha, psi_beta, i_alpha, i_beta)\n--\n\n"
     "Set the flux estimate (Wb) and the current sample (A) of the last sample, from\n"
     "which the next :meth:`update` integrates (instead of the current model) "
     "(cc_flux_set_state)."},
    {NULL, NULL, 0, NULL},
};

#define FLUX_M(name, field, type, flags) BLOCK_M(name, FluxBlock, cc_flux_t, field, type, flags)
static PyMemberDef Flux_members[] = {
    {"R_s", T_DOUBLE, offsetof(FluxBlock, R_s), READONLY, NULL},
    {"zeta_f", T_DOUBLE, offsetof(FluxBlock, zeta_f), READONLY, NULL},
    {"alpha_o", T_DOUBLE, offsetof(FluxBlock, alpha_o), READONLY, NULL},
    FLUX_M("L_d", L_d, T_DOUBLE, READONLY),
    FLUX_M("L_q", L_q, T_DOUBLE, READONLY),
    FLUX_M("psi_f", psi_f, T_DOUBLE, READONLY),
    FLUX_M("T_s", T_s, T_DOUBLE, READONLY),
    FLUX_M("w_min", w_min, T_DOUBLE, READONLY),
    FLUX_M("k_p", kp, T_DOUBLE, READONLY),
    FLUX_M("k_i", k_i, T_DOUBLE, READONLY),
    FLUX_M("_ki_T", ki_T, T_DOUBLE, READONLY),
    FLUX_M("_zT", zT, T_DOUBLE, READONLY),
    FLUX_M("_rT2", rT2, T_DOUBLE, READONLY),
    FLUX_M("_dL", dL, T_DOUBLE, READONLY),
    FLUX_M("psi_alpha", psi_alpha, T_DOUBLE, 0),
    FLUX_M("psi_beta", psi_beta, T_DOUBLE, 0),
    FLUX_M("theta_hat", theta_hat, T_DOUBLE, 0),
    FLUX_M("w_hat", w_hat, T_DOUBLE, 0),
    FLUX_M("eps", eps, T_DOUBLE, 0),
    FLUX_M("accel", accel, T_DOUBLE, 0),
    FLUX_M("_ia1", ia1, T_DOUBLE, 0),
    FLUX_M("_ib1", ib1, T_DOUBLE, 0),
    FLUX_M("_th_next", th_next, T_DOUBLE, 0),
    FLUX_M("_init", init, T_INT, 0),
    {NULL, 0, 0, 0, NULL},
};
#undef FLUX_M

BLOCK_TYPE(FluxType, "Flux", FluxBlock,
           "Flux(R_s, L_d, L_q, psi_f, T_s, zeta_f, w_min, k_p, k_i, alpha_o): a cc_flux_t "
           "(controller.FluxObserver)",
           Flux_init, Flux_methods, Flux_members, NULL);

/* -- supervision (core/cc_supervision.h) */
typedef struct {
    PyObject_HEAD
    cc_sup_t s;
} SupBlock;

/* Sup(*Supervisor.args()): the thresholds in the order of cc_sup_init */
static int Sup_init(SupBlock *self, PyObject *args, PyObject *kwds)
{
    double T_s, i_rail, i_res, du_stuck, i_min, rho_open, u_uv, u_ov, u_hyst;
    long long n_range, n_stuck, n_open_min, n_open_max, n_dc;
    (void)kwds;
    if (!PyArg_ParseTuple(args, "ddLddLddLLdddL", &T_s, &i_rail, &n_range, &i_res, &du_stuck,
                          &n_stuck, &i_min, &rho_open, &n_open_min, &n_open_max, &u_uv, &u_ov,
                          &u_hyst, &n_dc))
        return -1;
    cc_sup_init(&self->s, T_s, i_rail, n_range, i_res, du_stuck, n_stuck, i_min, rho_open,
                n_open_min, n_open_max, u_uv, u_ov, u_hyst, n_dc);
    return 0;
}

/* _check(i_a, i_b, u_dc, d_a, d_b, d_c, enable, mode, w_hat): cc_sup_check on the fields of
 * the ControlOutput that Supervisor.check hands over */
static PyObject *Sup_check(SupBlock *self, PyObject *args)
{
    double i_a, i_b, u_dc;
    cc_out_t o = {0};
    if (!PyArg_ParseTuple(args, "ddddddpLd", &i_a, &i_b, &u_dc, &o.d_a, &o.d_b, &o.d_c,
                          &o.enable, &o.mode, &o.w_hat))
        return NULL;
    return PyLong_FromLongLong(cc_sup_check(&self->s, i_a, i_b, u_dc, &o));
}

static PyObject *Sup_release_ok(SupBlock *self, PyObject *const *args, Py_ssize_t n,
                                PyObject *kw)
{
    static const char *const names[] = {"u_dc"};
    double v[1];
    if (block_args(args, n, kw, names, 1, 1, v, "release_ok()") < 0)
        return NULL;
    return PyBool_FromLong(cc_sup_release_ok(&self->s, v[0]));
}

static PyObject *Sup_reset_windows(SupBlock *self, PyObject *Py_UNUSED(ignored))
{
    cc_sup_reset_windows(&self->s);
    Py_RETURN_NONE;
}

static PyMethodDef Sup_methods[] = {
    {"_check", (PyCFunction)Sup_check, METH_VARARGS,
     "_check(i_a, i_b, u_dc, d_a, d_b, d_c, enable, mode, w_hat): cc_sup_check"},
    {"release_ok", (PyCFunction)(void (*)(void))Sup_release_ok, METH_FASTCALL | METH_KEYWORDS,
     "release_ok($self, /, u_dc)\n--\n\n"
     "Whether the latched detection may clear on a new enable (cc_sup_release_ok)."},
    {"_reset_windows", (PyCFunction)Sup_reset_windows, METH_NOARGS,
     "the detection windows emptied (cc_sup_reset_windows)"},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Sup_members[] = {
    BLOCK_M("latched", SupBlock, cc_sup_t, latched, T_LONGLONG, 0),
    BLOCK_M("detected_k", SupBlock, cc_sup_t, detected_k, T_LONGLONG, 0),
    {NULL, 0, 0, 0, NULL},
};

BLOCK_TYPE(SupType, "Sup", SupBlock, "Sup(*thresholds): a cc_sup_t (controller.Supervisor)",
           Sup_init, Sup_methods, Sup_members, NULL);

/* band_play(w_lo, w_mid, w_hi, h, y, w) and band_weights(w_lo, w_mid, w_hi, h, y): the
 * hybrids' band (cc_hybrid.h) for TransitionBand, whose fields are the cc_band_t's */
static int band_args(PyObject *const *args, Py_ssize_t n, Py_ssize_t want, cc_band_t *b,
                     double *v, const char *what)
{
    static const char *const names[] = {"w_lo", "w_mid", "w_hi", "h", "y", "w"};
    double a[6];
    if (block_args(args, n, NULL, names, want, want, a, what) < 0)
        return -1;
    cc_band_init(b, a[0], a[1], a[2], a[3]);
    for (Py_ssize_t j = 4; j < want; j++)
        v[j - 4] = a[j];
    return 0;
}

static PyObject *cctl_band_play(PyObject *Py_UNUSED(m), PyObject *const *args, Py_ssize_t n)
{
    cc_band_t b;
    double v[2];
    if (band_args(args, n, 6, &b, v, "band_play()") < 0)
        return NULL;
    return PyFloat_FromDouble(cc_band_play(&b, v[0], v[1]));
}

static PyObject *cctl_band_weights(PyObject *Py_UNUSED(m), PyObject *const *args, Py_ssize_t n)
{
    cc_band_t b;
    double v[1], lam, g;
    if (band_args(args, n, 5, &b, v, "band_weights()") < 0)
        return NULL;
    cc_band_weights(&b, v[0], &lam, &g);
    return Py_BuildValue("(dd)", lam, g);
}

/* smooth_sign(i_x, i_band, sine) and cross_saturation_offset(k_dq, i_q, L_d, L_q): the
 * compensation's per-period laws (core/cc_compensation.h) */
static PyObject *cctl_smooth_sign(PyObject *Py_UNUSED(m), PyObject *const *args, Py_ssize_t n,
                                  PyObject *kw)
{
    static const char *const names[] = {"i_x", "i_band", "sine"};
    double v[3];
    if (block_args(args, n, kw, names, 3, 3, v, "smooth_sign()") < 0)
        return NULL;
    return PyFloat_FromDouble(cc_smooth_sign(v[0], v[1], v[2] != 0.0));
}

static PyObject *cctl_cross_saturation_offset(PyObject *Py_UNUSED(m), PyObject *const *args,
                                              Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"k_dq", "i_q", "L_d", "L_q"};
    double v[4];
    if (block_args(args, n, kw, names, 4, 4, v, "cross_saturation_offset()") < 0)
        return NULL;
    return PyFloat_FromDouble(cc_cross_saturation_offset(v[0], v[1], v[2], v[3]));
}

/* svpwm(u_alpha, u_beta, u_dc): cc_svpwm's duties */
static PyObject *cctl_svpwm(PyObject *Py_UNUSED(m), PyObject *const *args, Py_ssize_t n,
                            PyObject *kw)
{
    static const char *const names[] = {"u_alpha", "u_beta", "u_dc"};
    double v[3], d[3];
    if (block_args(args, n, kw, names, 3, 3, v, "svpwm()") < 0)
        return NULL;
    cc_svpwm(v[0], v[1], v[2], d);
    return Py_BuildValue("(ddd)", d[0], d[1], d[2]);
}

/* limit_magnitude(x_1, x_2, x_max): cc_limit_magnitude's vector */
static PyObject *cctl_limit_magnitude(PyObject *Py_UNUSED(m), PyObject *const *args,
                                      Py_ssize_t n, PyObject *kw)
{
    static const char *const names[] = {"x_1", "x_2", "x_max"};
    double v[3];
    if (block_args(args, n, kw, names, 3, 3, v, "limit_magnitude()") < 0)
        return NULL;
    cc_limit_magnitude(&v[0], &v[1], v[2]);
    return Py_BuildValue("(dd)", v[0], v[1]);
}

/* hypot(x, y): the core's cc_hypot (cc_math.h), for its test against math.hypot */
static PyObject *cctl_hypot(PyObject *Py_UNUSED(m), PyObject *const *args, Py_ssize_t n)
{
    if (n != 2) {
        PyErr_SetString(PyExc_TypeError, "hypot(x, y) takes two floats");
        return NULL;
    }
    double x = PyFloat_AsDouble(args[0]);
    if (x == -1.0 && PyErr_Occurred())
        return NULL;
    double y = PyFloat_AsDouble(args[1]);
    if (y == -1.0 && PyErr_Occurred())
        return NULL;
    return PyFloat_FromDouble(cc_hypot(x, y));
}

static PyMethodDef module_methods[] = {
    {"hypot", (PyCFunction)(void (*)(void))cctl_hypot, METH_FASTCALL,
     "hypot(x, y): the core's cc_hypot, rounded as CPython 3.12+'s math.hypot"},
    {"band_play", (PyCFunction)(void (*)(void))cctl_band_play, METH_FASTCALL,
     "band_play(w_lo, w_mid, w_hi, h, y, w): cc_band_play"},
    {"band_weights", (PyCFunction)(void (*)(void))cctl_band_weights, METH_FASTCALL,
     "band_weights(w_lo, w_mid, w_hi, h, y): cc_band_weights's (lam, g)"},
    {"smooth_sign", (PyCFunction)(void (*)(void))cctl_smooth_sign, METH_FASTCALL | METH_KEYWORDS,
     "smooth_sign($module, /, i_x, i_band, sine)\n--\n\ncc_smooth_sign"},
    {"cross_saturation_offset", (PyCFunction)(void (*)(void))cctl_cross_saturation_offset,
     METH_FASTCALL | METH_KEYWORDS,
     "cross_saturation_offset($module, /, k_dq, i_q, L_d, L_q)\n--\n\ncc_cross_saturation_offset"},
    {"svpwm", (PyCFunction)(void (*)(void))cctl_svpwm, METH_FASTCALL | METH_KEYWORDS,
     "svpwm($module, /, u_alpha, u_beta, u_dc)\n--\n\ncc_svpwm's duties (d_a, d_b, d_c)"},
    {"limit_magnitude", (PyCFunction)(void (*)(void))cctl_limit_magnitude,
     METH_FASTCALL | METH_KEYWORDS,
     "limit_magnitude($module, /, x_1, x_2, x_max)\n--\n\ncc_limit_magnitude's vector"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "controller._cctl",
    "The controller core bound to Python (see controller._compiled).", -1, module_methods,
};

PyMODINIT_FUNC PyInit__cctl(void)
{
    if (PyType_Ready(&CoreType) < 0)
        return NULL;
    static const char *pub[5] = {"theta_hat", "w_hat", "err", "i_alpha_f", "i_beta_f"};
    for (int j = 0; j < 5; j++)
        if ((s_pub[j] = PyUnicode_InternFromString(pub[j])) == NULL)
            return NULL;
    if ((s_update = PyUnicode_InternFromString("update")) == NULL
        || (s_injection = PyUnicode_InternFromString("injection")) == NULL
        || (s_reset = PyUnicode_InternFromString("reset")) == NULL
        || (s_hf_current_next = PyUnicode_InternFromString("hf_current_next")) == NULL
        || (s_saliency_offset = PyUnicode_InternFromString("saliency_offset")) == NULL)
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
    PyTypeObject *blocks[] = {&PiType, &PllType, &PolarityType, &FluxType, &SupType};
    for (size_t j = 0; j < sizeof blocks / sizeof blocks[0]; j++)
        if (PyModule_AddType(m, blocks[j]) < 0) { /* readies the type too */
            Py_DECREF(m);
            return NULL;
        }
    PyModule_AddIntConstant(m, "KIND_TTDQ", CC_EST_TT_DQ);
    PyModule_AddIntConstant(m, "KIND_TTAB", CC_EST_TT_AB);
    PyModule_AddIntConstant(m, "KIND_SFHF", CC_EST_SFHF);
    PyModule_AddIntConstant(m, "KIND_SQW", CC_EST_SQUARE_WAVE);
    PyModule_AddIntConstant(m, "KIND_SENSORED", CC_EST_SENSORED);
    PyModule_AddIntConstant(m, "KIND_HYB_TTDQ", CC_EST_HYBRID_TT_DQ);
    PyModule_AddIntConstant(m, "KIND_HYB_SQW", CC_EST_HYBRID_SQUARE_WAVE);
    PyModule_AddIntConstant(m, "KIND_SELF_DEMOD", CC_EST_SELF_DEMOD);
    PyModule_AddIntConstant(m, "KIND_EPF", CC_EST_EPF);
    PyModule_AddIntConstant(m, "KIND_EXTERNAL", CC_EST_EXTERNAL);
    /* the longest CIC delay line, the square-wave estimators' option M's maximum */
    PyModule_AddIntConstant(m, "CIC_MAX", CC_CIC_MAX);
    return m;
}
