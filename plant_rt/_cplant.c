/* The CPython binding of the plant core (plant_rt/core/, plain C99).
 *
 * It hands structs across and nothing else: the design parameters arrive as
 * the fields of plant_pars in order (plant_rt._plant._core_pars makes
 * them), the states as plain floats, the load profile and the noise source
 * as callables; no attribute of a Python object is read by name. The
 * equations are in the core, one file per block.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "core/plant.h"
#include "core/plant_layout.h"
#include "core/plant_protection.h"
#include "core/plant_pwm.h" /* dead_time_error, device_drop_error */
#include "core/plant_sensors.h"

typedef struct {
    PyObject_HEAD
    plant pl;
    PyObject *load_tau; /* LoadProfile.tau, or NULL for a constant load */
    PyObject *gauss;    /* random.Random.gauss of the sensors' generator */
} Core;

/* ------------------------------------------------------------- callbacks */
static int call_load(void *ctx, double t, double w_m, double *tau)
{
    Core *s = (Core *)ctx;
    PyObject *r = PyObject_CallFunction(s->load_tau, "dd", t, w_m);
    if (r == NULL) return -1;
    *tau = PyFloat_AsDouble(r);
    Py_DECREF(r);
    return (*tau == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

static int call_gauss(void *ctx, double sd, double *out)
{
    Core *s = (Core *)ctx;
    PyObject *r = PyObject_CallFunction(s->gauss, "dd", 0.0, sd);
    if (r == NULL) return -1;
    *out = PyFloat_AsDouble(r);
    Py_DECREF(r);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 0;
}

/* ---------------------------------------------------------- parameters */
#define PARS_DOC                                                                                   \
    "(n_p, R_s, L_d, L_q, psi_f, J, b, i_max, sat_sigma, sat_i_sat, c_dq, saturation, cross, "     \
    "T_s, substeps, t_delay, switching, peak, u_dc, t_dead, v_ce, v_f, r_dc, c_dc)"

static int parse_pars(PyObject *args, plant_pars *p)
{
    plant_machine_pars *m = &p->machine;
    return PyArg_ParseTuple(args, "dddddddddddppdidppdddddd", &m->n_p, &m->R_s, &m->L_d, &m->L_q,
                            &m->psi_f, &m->J, &m->b, &m->i_max, &m->sat_sigma, &m->sat_i_sat,
                            &m->c_dq, &m->saturation, &m->cross, &p->T_s, &p->substeps,
                            &p->t_delay, &p->switching, &p->peak, &p->u_dc, &p->t_dead, &p->v_ce,
                            &p->v_f, &p->r_dc, &p->c_dc);
}

static int Core_init(Core *s, PyObject *args, PyObject *kw)
{
    plant_pars p;
    if (kw != NULL && PyDict_GET_SIZE(kw)) {
        PyErr_SetString(PyExc_TypeError, "Core" PARS_DOC " takes no keywords");
        return -1;
    }
    if (!parse_pars(args, &p)) return -1;
    if (plant_init(&s->pl, &p) != PLANT_OK) {
        PyErr_Format(PyExc_ValueError, "plant core: T_s > 0, substeps in 1..%d, t_delay in [0, T_s)",
                     PLANT_MAX_SUBSTEPS);
        return -1;
    }
    s->pl.load = call_load;
    s->pl.load_ctx = s;
    s->pl.sens.g[0] = s->pl.sens.g[1] = s->pl.sens.g[2] = 1.0;
    s->pl.sens.gain_u = 1.0;
    s->pl.sens.gauss = call_gauss;
    s->pl.sens.gauss_ctx = s;
    Py_CLEAR(s->load_tau);
    Py_CLEAR(s->gauss);
    return 0;
}

static PyObject *Core_set_pars(Core *s, PyObject *args)
{
    plant_pars p;
    if (!parse_pars(args, &p)) return NULL;
    if (plant_set_pars(&s->pl, &p) != PLANT_OK) {
        PyErr_SetString(PyExc_ValueError,
                        "set_pars: T_s, substeps, the sensor delay and the inverter model cannot "
                        "change after the plant is built");
        return NULL;
    }
    Py_RETURN_NONE;
}

/* ------------------------------------------------------------- methods */
static int get_doubles(PyObject *const *args, Py_ssize_t n, double *v)
{
    for (Py_ssize_t k = 0; k < n; k++) {
        v[k] = PyFloat_AsDouble(args[k]);
        if (v[k] == -1.0 && PyErr_Occurred()) return -1;
    }
    return 0;
}

static PyObject *state_tuple(const plant *pl)
{
    return Py_BuildValue("(ddddddd)", pl->x.i_d, pl->x.i_q, pl->x.w_m, pl->x.th_m, pl->u_dc,
                         pl->u_al, pl->u_be);
}

static PyObject *Core_step(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    double v[4];
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "step(d_a, d_b, d_c, t0) takes 4 arguments");
        return NULL;
    }
    if (get_doubles(args, 4, v) < 0) return NULL;
    if (plant_step(&s->pl, v[0], v[1], v[2], v[3]) != PLANT_OK) return NULL;
    return state_tuple(&s->pl);
}

static PyObject *Core_step_off(Core *s, PyObject *arg)
{
    double t0 = PyFloat_AsDouble(arg);
    if (t0 == -1.0 && PyErr_Occurred()) return NULL;
    if (plant_step_off(&s->pl, t0) != PLANT_OK) return NULL;
    return state_tuple(&s->pl);
}

static PyObject *Core_set_legs(Core *s, PyObject *args)
{
    int leg[3];
    if (!PyArg_ParseTuple(args, "iii", &leg[0], &leg[1], &leg[2])) return NULL;
    if (plant_set_legs(&s->pl, leg) != PLANT_OK) {
        PyErr_SetString(PyExc_ValueError, "set_legs: each leg's fault is 0 to 3 (PLANT_LEG_*)");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyObject *Core_set_metering(Core *s, PyObject *arg)
{
    int on = PyObject_IsTrue(arg);
    if (on < 0) return NULL;
    s->pl.metering = on;
    Py_RETURN_NONE;
}

static PyObject *Core_meter(Core *s, PyObject *unused)
{
    const plant_meter *e = &s->pl.meter;
    return Py_BuildValue("(dddddddd)", e->e_in, e->e_cu, e->e_em, e->e_fric, e->e_load, e->q_a,
                         e->q_b, e->q_c);
}

static PyObject *Core_out_of_range(Core *s, PyObject *unused)
{
    return PyLong_FromLong(s->pl.n_out);
}

static PyObject *Core_currents(Core *s, PyObject *unused)
{
    double i[3];
    plant_currents(&s->pl, i);
    return Py_BuildValue("(ddd)", i[0], i[1], i[2]);
}

static PyObject *Core_back_emf(Core *s, PyObject *unused)
{
    double e[3];
    plant_back_emf(&s->pl, e);
    return Py_BuildValue("(ddd)", e[0], e[1], e[2]);
}

static PyObject *Core_torque(Core *s, PyObject *unused)
{
    return PyFloat_FromDouble(plant_machine_torque(&s->pl.m, s->pl.x.i_d, s->pl.x.i_q));
}

static PyObject *Core_step_n(Core *s, PyObject *args)
{
    long k0;
    Py_buffer buf;
    if (!PyArg_ParseTuple(args, "ly*", &k0, &buf)) return NULL;
    if (buf.len % (Py_ssize_t)(3 * sizeof(double)) != 0) {
        PyBuffer_Release(&buf);
        PyErr_SetString(PyExc_ValueError, "step_n: the duties are 3 doubles per period");
        return NULL;
    }
    long n = (long)(buf.len / (Py_ssize_t)(3 * sizeof(double)));
    PyObject *out = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)(n * sizeof(plant_out)));
    if (out == NULL) {
        PyBuffer_Release(&buf);
        return NULL;
    }
    long done = 0;
    int e = plant_step_n(&s->pl, k0, n, (const double *)buf.buf,
                         (plant_out *)PyBytes_AS_STRING(out), &done);
    PyBuffer_Release(&buf);
    if (e != PLANT_OK) {
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

static PyObject *Core_set_state(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    double v[5];
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "set_state(i_d, i_q, w_m, th_m, u_dc, imposed)");
        return NULL;
    }
    if (get_doubles(args, 5, v) < 0) return NULL;
    int imposed = PyObject_IsTrue(args[5]);
    if (imposed < 0) return NULL;
    s->pl.x.i_d = v[0];
    s->pl.x.i_q = v[1];
    s->pl.x.w_m = v[2];
    s->pl.x.th_m = v[3];
    s->pl.u_dc = v[4];
    s->pl.imposed = imposed;
    Py_RETURN_NONE;
}

static PyObject *Core_set_load(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "set_load(tau, tau_const)");
        return NULL;
    }
    if (args[1] == Py_None) {
        if (!PyCallable_Check(args[0])) {
            PyErr_SetString(PyExc_TypeError, "set_load: tau must be callable");
            return NULL;
        }
        Py_INCREF(args[0]);
        Py_XSETREF(s->load_tau, args[0]);
        s->pl.load_const = 0;
        Py_RETURN_NONE;
    }
    double tau = PyFloat_AsDouble(args[1]);
    if (tau == -1.0 && PyErr_Occurred()) return NULL;
    Py_CLEAR(s->load_tau);
    s->pl.load_const = 1;
    s->pl.tau_const = tau;
    Py_RETURN_NONE;
}

static PyObject *Core_meas(Core *s, PyObject *unused)
{
    const double *m = s->pl.meas;
    return Py_BuildValue("(dddd)", m[0], m[1], m[2], m[3]);
}

static PyObject *Core_set_sensors(Core *s, PyObject *args)
{
    plant_sensors *q = &s->pl.sens;
    PyObject *gauss;
    if (!PyArg_ParseTuple(args, "ddddddddddddddO", &q->g[0], &q->g[1], &q->g[2], &q->o[0],
                          &q->o[1], &q->o[2], &q->lsb_i, &q->code_max, &q->noise_i, &q->gain_u,
                          &q->off_u, &q->lsb_u, &q->ucode_max, &q->noise_u, &gauss))
        return NULL;
    if (!PyCallable_Check(gauss)) {
        PyErr_SetString(PyExc_TypeError, "set_sensors: gauss must be callable");
        return NULL;
    }
    Py_INCREF(gauss);
    Py_XSETREF(s->gauss, gauss);
    Py_RETURN_NONE;
}

static PyObject *Core_measure(Core *s, PyObject *const *args, Py_ssize_t nargs)
{
    double i[3], u, out[4];
    if (nargs == 4) {
        if (get_doubles(args, 3, i) < 0 || get_doubles(args + 3, 1, &u) < 0) return NULL;
    } else if (nargs == 0) {
        plant_currents(&s->pl, i);
        u = s->pl.u_dc;
    } else {
        PyErr_SetString(PyExc_TypeError, "measure() or measure(i_a, i_b, i_c, u_dc)");
        return NULL;
    }
    if (s->gauss == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "measure() before set_sensors()");
        return NULL;
    }
    switch (plant_sensors_measure(&s->pl.sens, i, u, out)) {
    case PLANT_SENSE_OK:
        return Py_BuildValue("(dddd)", out[0], out[1], out[2], out[3]);
    case PLANT_SENSE_NAN:
        PyErr_SetString(PyExc_ValueError, "cannot convert float NaN to integer");
        return NULL;
    case PLANT_SENSE_INF:
        PyErr_SetString(PyExc_OverflowError, "cannot convert float infinity to integer");
        return NULL;
    default: /* the noise source raised */
        return NULL;
    }
}

static PyObject *Core_address(Core *s, PyObject *unused)
{
    return PyLong_FromVoidPtr(&s->pl);
}

static PyObject *Core_state(Core *s, PyObject *unused)
{
    return state_tuple(&s->pl);
}

static PyObject *Core_load_const(Core *s, PyObject *unused)
{
    if (!s->pl.load_const) Py_RETURN_NONE;
    return PyFloat_FromDouble(s->pl.tau_const);
}

static void Core_dealloc(Core *s)
{
    Py_XDECREF(s->load_tau);
    Py_XDECREF(s->gauss);
    Py_TYPE(s)->tp_free((PyObject *)s);
}

static PyMethodDef Core_methods[] = {
    {"step", (PyCFunction)(void (*)(void))Core_step, METH_FASTCALL,
     "step(d_a, d_b, d_c, t0) -> (i_d, i_q, w_m, th_m, u_dc, u_al, u_be): one enabled period"},
    {"step_off", (PyCFunction)Core_step_off, METH_O,
     "step_off(t0) -> (i_d, i_q, w_m, th_m, u_dc, u_al, u_be): one period, all switches open"},
    {"set_legs", (PyCFunction)Core_set_legs, METH_VARARGS,
     "set_legs(a, b, c): the open-leg fault of each leg from the next period (plant_leg.h: "
     "0 none, 1 open phase, 2 open upper switch, 3 open lower switch)"},
    {"set_metering", (PyCFunction)Core_set_metering, METH_O,
     "set_metering(on): integrate the energy flows with the states"},
    {"meter", (PyCFunction)Core_meter, METH_NOARGS,
     "meter() -> (e_in, e_cu, e_em, e_fric, e_load, q_a, q_b, q_c)"},
    {"out_of_range", (PyCFunction)Core_out_of_range, METH_NOARGS,
     "out_of_range() -> the periods that ended outside the flux map's checked range"},
    {"currents", (PyCFunction)Core_currents, METH_NOARGS, "currents() -> (i_a, i_b, i_c) now"},
    {"torque", (PyCFunction)Core_torque, METH_NOARGS, "torque() -> tau_e now (N m)"},
    {"back_emf", (PyCFunction)Core_back_emf, METH_NOARGS, "back_emf() -> (e_a, e_b, e_c) now (V)"},
    {"step_n", (PyCFunction)Core_step_n, METH_VARARGS,
     "step_n(k0, duties) -> bytes: periods k0.. with 3 doubles of duties each; the states "
     "(i_d, i_q, w_m, th_m, u_dc, u_al, u_be) after each, 7 doubles a period"},
    {"set_pars", (PyCFunction)Core_set_pars, METH_VARARGS,
     "set_pars" PARS_DOC ": new parameters between two periods; the states are kept"},
    {"set_state", (PyCFunction)(void (*)(void))Core_set_state, METH_FASTCALL,
     "set_state(i_d, i_q, w_m, th_m, u_dc, imposed): take over the plant's state"},
    {"set_load", (PyCFunction)(void (*)(void))Core_set_load, METH_FASTCALL,
     "set_load(tau, tau_const): tau(t, w_m) the load torque; tau_const a float for a constant "
     "load (then tau is not called)"},
    {"meas", (PyCFunction)Core_meas, METH_NOARGS,
     "meas() -> (i_a, i_b, i_c, u_dc) recorded at the sensor instant of the last period"},
    {"set_sensors", (PyCFunction)Core_set_sensors, METH_VARARGS,
     "set_sensors(g_a, g_b, g_c, o_a, o_b, o_c, lsb_i, code_max, noise_i, gain_u_dc, "
     "offset_u_dc, lsb_u, ucode_max, noise_u, gauss): the ADC and its noise source "
     "gauss(mu, sigma)"},
    {"measure", (PyCFunction)(void (*)(void))Core_measure, METH_FASTCALL,
     "measure([i_a, i_b, i_c, u_dc]) -> measured (i_a, i_b, i_c, u_dc)"},
    {"address", (PyCFunction)Core_address, METH_NOARGS,
     "address() -> the address of the instance (plant *), for a C caller that steps it "
     "(the native plant node); valid while this object lives"},
    {"state", (PyCFunction)Core_state, METH_NOARGS,
     "state() -> (i_d, i_q, w_m, th_m, u_dc, u_al, u_be) now"},
    {"load_const", (PyCFunction)Core_load_const, METH_NOARGS,
     "load_const() -> the constant load torque (N m), or None for a load profile"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject CoreType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "plant_rt._cplant.Core",
    .tp_doc = "Core" PARS_DOC ": the plant core's instance (plant_rt/core/plant.h)",
    .tp_basicsize = sizeof(Core),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Core_init,
    .tp_dealloc = (destructor)Core_dealloc,
    .tp_methods = Core_methods,
};

/* ------------------------------------------------------ module functions */
static PyObject *mod_protection_check(PyObject *unused, PyObject *const *args, Py_ssize_t nargs)
{
    double v[8];
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError,
                        "protection_check(i_trip, u_dc_trip, w_m_trip, i_a, i_b, i_c, u_dc, w_m)");
        return NULL;
    }
    if (get_doubles(args, 8, v) < 0) return NULL;
    plant_protection p = {v[0], v[1], v[2]};
    return PyLong_FromLong(plant_protection_check(&p, v[3], v[4], v[5], v[6], v[7]));
}

static PyObject *mod_encoder_angle(PyObject *unused, PyObject *args)
{
    double th, w, delay;
    long counts;
    if (!PyArg_ParseTuple(args, "dddl", &th, &w, &delay, &counts)) return NULL;
    return PyFloat_FromDouble(plant_encoder_angle(th, w, delay, counts));
}

/* machine(n_p, L_d, L_q, psi_f, sigma, i_sat, c_dq, saturation, cross, i_d, i_q) */
static PyObject *mod_machine(PyObject *unused, PyObject *args)
{
    plant_machine_pars p = {0};
    double i_d, i_q;
    if (!PyArg_ParseTuple(args, "ddddddddppdd", &p.n_p, &p.L_d, &p.L_q, &p.psi_f, &p.i_max,
                          &p.sat_sigma, &p.sat_i_sat, &p.c_dq, &p.saturation, &p.cross, &i_d,
                          &i_q))
        return NULL;
    p.J = 1.0;
    plant_machine m;
    plant_machine_init(&m, &p);
    double out[5];
    if (m.cross) {
        plant_flux_dq(&m, i_d, i_q, out);
    } else {
        plant_flux_d(&m, i_d, &out[0], &out[2]);
        out[1] = m.L_q * i_q;
        out[3] = 0.0;
        out[4] = m.L_q;
    }
    return Py_BuildValue("(dddddd)", out[0], out[1], out[2], out[3], out[4],
                         plant_machine_torque(&m, i_d, i_q));
}

static PyObject *mod_dead_time_error(PyObject *unused, PyObject *const *args, Py_ssize_t nargs)
{
    double v[4];
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "dead_time_error(i_x, u_dc, t_dead, T_s)");
        return NULL;
    }
    if (get_doubles(args, 4, v) < 0) return NULL;
    return PyFloat_FromDouble(plant_dead_time_error(v[0], v[1], v[2], v[3]));
}

static PyObject *mod_device_drop_error(PyObject *unused, PyObject *const *args, Py_ssize_t nargs)
{
    double v[4];
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "device_drop_error(i_x, d_x, v_ce, v_f)");
        return NULL;
    }
    if (get_doubles(args, 4, v) < 0) return NULL;
    return PyFloat_FromDouble(plant_device_drop_error(v[0], v[1], v[2], v[3]));
}

/* layout() -> (names, numbers): the plant instance's layout as this build compiled it
 * (plant_layout.h; the native node library exports the same, _plant_native.py compares) */
static PyObject *mod_layout(PyObject *unused, PyObject *noargs)
{
    size_t n = plant_layout(NULL, 0);
    size_t *v = PyMem_Calloc(n, sizeof *v);
    if (v == NULL) return PyErr_NoMemory();
    plant_layout(v, n);
    PyObject *nums = PyTuple_New((Py_ssize_t)n);
    for (size_t i = 0; nums != NULL && i < n; i++) {
        PyObject *x = PyLong_FromSize_t(v[i]);
        if (x == NULL) Py_CLEAR(nums);
        else PyTuple_SET_ITEM(nums, (Py_ssize_t)i, x);
    }
    PyMem_Free(v);
    if (nums == NULL) return NULL;
    return Py_BuildValue("(sN)", plant_layout_names(), nums);
}

static PyMethodDef module_methods[] = {
    {"machine", (PyCFunction)mod_machine, METH_VARARGS,
     "machine(n_p, L_d, L_q, psi_f, i_max, sigma, i_sat, c_dq, saturation, cross, i_d, i_q) -> "
     "(psi_d, psi_q, L_dd, L_dq, L_qq, tau_e): the flux map and the torque"},
    {"dead_time_error", (PyCFunction)(void (*)(void))mod_dead_time_error, METH_FASTCALL,
     "dead_time_error(i_x, u_dc, t_dead, T_s) -> the period-mean pole-voltage error (V)"},
    {"device_drop_error", (PyCFunction)(void (*)(void))mod_device_drop_error, METH_FASTCALL,
     "device_drop_error(i_x, d_x, v_ce, v_f) -> the period-mean device drop (V)"},
    {"protection_check", (PyCFunction)(void (*)(void))mod_protection_check, METH_FASTCALL,
     "protection_check(i_trip, u_dc_trip, w_m_trip, i_a, i_b, i_c, u_dc, w_m) -> fault code"},
    {"encoder_angle", (PyCFunction)mod_encoder_angle, METH_VARARGS,
     "encoder_angle(theta_m, w_m, delay_s, counts) -> the angle a position sensor reports"},
    {"layout", (PyCFunction)mod_layout, METH_NOARGS,
     "layout() -> (names, numbers): sizeof(plant), its blocks' sizes and its members' offsets "
     "as this build compiled them (plant_rt/core/plant_layout.h)"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "plant_rt._cplant",
    "The CPython binding of the plant core (plant_rt/core/).", -1, module_methods,
};

PyMODINIT_FUNC PyInit__cplant(void)
{
    if (PyType_Ready(&CoreType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL) return NULL;
    Py_INCREF(&CoreType);
    if (PyModule_AddObject(m, "Core", (PyObject *)&CoreType) < 0
        || PyModule_AddIntConstant(m, "FAULT_NONE", PLANT_FAULT_NONE) < 0
        || PyModule_AddIntConstant(m, "FAULT_WATCHDOG", PLANT_FAULT_WATCHDOG) < 0
        || PyModule_AddIntConstant(m, "FAULT_OVER_CURRENT", PLANT_FAULT_OVER_CURRENT) < 0
        || PyModule_AddIntConstant(m, "FAULT_OVER_VOLTAGE", PLANT_FAULT_OVER_VOLTAGE) < 0
        || PyModule_AddIntConstant(m, "FAULT_OVER_SPEED", PLANT_FAULT_OVER_SPEED) < 0
        || PyModule_AddIntConstant(m, "MAX_SUBSTEPS", PLANT_MAX_SUBSTEPS) < 0
        || PyModule_AddObject(m, "FLUX_RANGE", PyFloat_FromDouble(PLANT_FLUX_RANGE)) < 0
        || PyModule_AddObject(m, "FLUX_FADE", PyFloat_FromDouble(PLANT_FLUX_FADE)) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
