/* What a real drive does against its inverter and sensors (controller/_compensation.py
 * derives each law and its constants):
 *
 *   dead-time feed-forward: the mean pole-voltage error of a leg over a period,
 *       i_x > 0:  -t_dead/T_s u_dc - (d_x v_ce + (1 - d_x) v_f)
 *       i_x < 0:  +t_dead/T_s u_dc + (d_x v_f + (1 - d_x) v_ce),
 *     the current's sign smoothed over the period's ripple i_h of amplitude i_band
 *     (mean of sign(i + i_h): i / i_band for a triangle, (2/pi) asin(i / i_band) for a
 *     sinusoid), added back to the duties as -du_x / u_dc;
 *   cross-saturation: the HF estimators lock at delta = -1/2 atan(2 L_dq / (L_q - L_d))
 *     with L_dq = k_dq i_q; the correction adds -delta back;
 *   offset calibration: the mean of n current samples at standstill, PWM disabled,
 *     subtracted from every later sample.
 */
#ifndef CC_COMPENSATION_H
#define CC_COMPENSATION_H

typedef struct {
    double k_dt;   /* t_dead / T_s */
    double v_ce;   /* transistor on-state drop (V) */
    double v_f;    /* diode forward drop (V) */
    double i_band; /* smoothing band of the current sign (A); 0: hard sign */
    int sine;      /* sinusoidal (1) or triangular (0) ripple law */
} cc_deadtime_t;

void cc_deadtime_init(cc_deadtime_t *dt, double T_s, double t_dead, double v_ce, double v_f,
                      double i_band, int sine);
/* the mean of sign(i_x + i_h) over one period of a ripple of amplitude i_band */
double cc_smooth_sign(double i_x, double i_band, int sine);
/* the expected mean pole-voltage error (V) of a leg with duty d_x for the current i_x */
double cc_deadtime_voltage(const cc_deadtime_t *dt, double i_x, double u_dc, double d_x);
/* the duties d[3] with each leg's expected error added back, clipped to [0, 1] */
void cc_deadtime_duties(const cc_deadtime_t *dt, double d[3], double i_a, double i_b,
                        double i_c, double u_dc);

/* the angle (rad) the HF estimators lock away from the rotor, theta_hat - theta_e */
double cc_cross_saturation_offset(double k_dq, double i_q, double L_d, double L_q);

typedef struct {
    long long n, k;            /* samples to average, taken */
    double s_a, s_b, s_c;      /* their sums */
    double o_a, o_b, o_c;      /* the offsets in use (A) */
} cc_offset_cal_t;

void cc_offset_cal_init(cc_offset_cal_t *cal, long long n);
/* a new calibration; the offsets in use stay until it ends */
void cc_offset_cal_restart(cc_offset_cal_t *cal);
/* one standstill sample; the offsets are updated when the n-th arrives */
void cc_offset_cal_add(cc_offset_cal_t *cal, double i_a, double i_b, double i_c);

#endif
