/* The layout of the plant instance (plant, plant.h) as one build compiled it.
 *
 * The plant core is compiled twice: into the CPython binding (plant_rt/_cplant.c)
 * and into the native node library (bench/nodes/native/), which steps the binding's
 * instance by its address. Both are built from these headers, but at different
 * times: an extension built before a change of plant.h beside a library built
 * after it would step a struct of another shape. Each build exports the numbers
 * below; bench/nodes/native/_plant_native.py compares them before the library
 * touches an instance.
 *
 * The numbers: sizeof(plant), the size of each block the instance embeds, and
 * the offset of every member of plant (PLANT_LAYOUT_MEMBERS: a member added to
 * plant belongs in this list).
 */
#ifndef PLANT_LAYOUT_H
#define PLANT_LAYOUT_H

#include <stddef.h>

/* The embedded blocks whose sizes are checked. */
#define PLANT_LAYOUT_BLOCKS(X)                                                                     \
    X(plant_machine) X(plant_pwm) X(plant_dclink) X(plant_sensors) X(plant_state) X(plant_trig)    \
        X(plant_meter)

/* The members of plant whose offsets are checked, in declaration order. */
#define PLANT_LAYOUT_MEMBERS(X)                                                                    \
    X(m) X(pwm) X(dc) X(sens) X(x) X(trig) X(u_dc) X(imposed) X(u_al) X(u_be) X(meas) X(T_s) X(h)  \
        X(i_eps) X(t_meas) X(substeps) X(v_ce) X(v_f) X(t_dead) X(switching) X(drops)             \
            X(avg_general) X(grid) X(n_grid) X(cuts) X(n_cuts) X(seg_a) X(seg_b) X(seg_j)          \
                X(n_segs) X(load) X(load_ctx) X(load_const) X(tau_const) X(err) X(leg) X(any_leg)  \
                    X(metering) X(meter) X(n_out) X(out_r2)

/* Writes up to n of the numbers to out (sizeof(plant), the blocks' sizes, the
 * members' offsets, in that order); returns how many there are. */
size_t plant_layout(size_t *out, size_t n);

/* The numbers' names, separated by ";", in the same order. */
const char *plant_layout_names(void);

#endif
