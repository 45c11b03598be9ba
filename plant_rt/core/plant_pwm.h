/* The inverter: symmetric-carrier PWM timeline with dead time, and the
 * period-mean errors of the average model.
 *
 * Carrier (plant_rt._pwm): a symmetric triangle at f_sw = 1 / T_s whose
 * extremum chosen by sample_at falls on every period boundary. With duty d
 * and the carrier's peak on the boundary a leg is low on [0, (1 - d) T/2),
 * high to (1 + d) T/2, low to T; with the valley on the boundary it is high
 * on [0, d T/2), low to T - d T/2, high to T. Each edge is followed by a
 * dead interval of t_dead in which both switches are open (regular-sampled
 * symmetric PWM and its dead-time voltage error dv = -sign(i) u_dc t_dead /
 * T_s, Holmes and Lipo, Pulse Width Modulation for Power Converters, 2003).
 * Device drops: v_ce on a conducting transistor, v_f on a diode, weighted
 * by the leg's time on each rail.
 */
#ifndef PLANT_PWM_H
#define PLANT_PWM_H

#define PLANT_MAX_PTS 12 /* change points of one leg in one period (at most 8) */

typedef struct {
    double T_s, t_dead;
    int peak;           /* the carrier's peak falls on the period boundary */
    int cmd[3];         /* the commanded level of each leg at the period's end */
    double dead_end[3]; /* a dead interval carried into the next period (s) */
} plant_pwm;

void plant_pwm_init(plant_pwm *p, double T_s, double t_dead, int peak);

/* All switches were opened for a period. */
void plant_pwm_disable(plant_pwm *p);

/* Change points (t, state) of leg x in this period for duty d in [0, 1],
 * the first at t = 0; returns their number (<= PLANT_MAX_PTS). */
int plant_pwm_leg(plant_pwm *p, int x, double d, double *pt, int *ps);

/* clamp to [0, 1] (NaN to 0) */
double plant_clamp_duty(double d);

/* Average model: the period-mean pole-voltage error of the dead time,
 * -sign(i_x) u_dc t_dead / T_s. */
double plant_dead_time_error(double i_x, double u_dc, double t_dead, double T_s);

/* Average model: the period-mean device drop of a leg on the positive rail
 * for the fraction d_x. */
double plant_device_drop_error(double i_x, double d_x, double v_ce, double v_f);

#endif
