/* Sensing: the phase-current and DC-link ADC, and the position encoder.
 *
 * ADC (plant_rt._sensors.SensorPars): measured = gain x true + offset +
 * noise, quantised to the nearest code of a mid-tread converter,
 * code = floor(x / lsb + 1/2) clamped to the converter's range: bipolar
 * codes [-2^(bits-1), 2^(bits-1) - 1] for the currents, unipolar
 * [0, 2^bits - 1] for the voltage.
 * Encoder: the angle encoder_delay_s earlier at the present speed, reported
 * as the whole count reached of N per revolution.
 */
#ifndef PLANT_SENSORS_H
#define PLANT_SENSORS_H

/* Gaussian noise of standard deviation sd; returns 0, or nonzero on error. */
typedef int (*plant_gauss_fn)(void *ctx, double sd, double *out);

typedef struct {
    double g[3], o[3];           /* current gain and offset per phase */
    double lsb_i, code_max;      /* current ADC step (A, 0: none) and largest code */
    double noise_i;              /* current noise (A rms) */
    double gain_u, off_u;        /* voltage gain and offset */
    double lsb_u, ucode_max;     /* voltage ADC step (V, 0: none) and largest code */
    double noise_u;              /* voltage noise (V rms) */
    plant_gauss_fn gauss;        /* the noise source (used only with noise > 0) */
    void *gauss_ctx;
} plant_sensors;

/* Error codes of plant_sensors_measure. */
enum { PLANT_SENSE_OK = 0, PLANT_SENSE_NOISE = 1, PLANT_SENSE_NAN = 2, PLANT_SENSE_INF = 3 };

/* The measured (i_a, i_b, i_c, u_dc) of the true values. */
int plant_sensors_measure(const plant_sensors *s, const double i[3], double u_dc, double out[4]);

/* The mechanical angle a position sensor reports (rad, [0, 2 pi)). */
double plant_encoder_angle(double theta_m, double w_m, double delay_s, long counts);

#endif
