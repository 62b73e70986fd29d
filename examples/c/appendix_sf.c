/* The appendix A state feedback. See appendix_sf.h; each line names the Python it ports. */
#include "appendix_sf.h"

#include <math.h>

/* twin.converters.ball_position_m: x1 = (0.0693 * V) + 0.0018 (eq 6.3.1) */
static double ball_position_m(double v, const sf_calibration *c)
{
    return (c->ball_gain_m_per_v * v) + c->ball_offset_m;
}

/* twin.converters.beam_angle_rad: ((143.22657649*(V - 5.002) + 718.59375)/7) * (3.141592654/180) */
static double beam_angle_rad(double v, const sf_calibration *c)
{
    double deg = (c->angle_gain_deg_per_v * (v - c->angle_reference_v) + c->angle_reference_motor_deg) /
                 c->angle_gear_ratio;
    return deg * (c->software_pi / 180.0);
}

/* twin.converters.dac_command_v: adat = (value/9.6) + 2.5 */
static double dac_command_v(double motor_v, const sf_calibration *c)
{
    return (motor_v / c->command_gain_v_per_v) + c->command_zero_v;
}

/* twin.converters.motor_volts_from_command: u(k) = (adat - 2.5)*9.6 */
static double motor_volts_from_command(double command_v, const sf_calibration *c)
{
    return (command_v - c->command_zero_v) * c->command_gain_v_per_v;
}

/* twin.converters.clip_command_v: min(max(c, low), high), Python's min/max on finite floats */
static double clip_command_v(double command_v, const sf_calibration *c)
{
    double m = (c->command_low_v > command_v) ? c->command_low_v : command_v;
    return (m > c->command_high_v) ? c->command_high_v : m;
}

int sf_start(sf_state *s, const sf_calibration *cal, double ball_v, double angle_v)
{
    if (!isfinite(ball_v) || !isfinite(angle_v)) return -1;
    s->cal = *cal;
    s->k = 1;
    s->x1 = ball_position_m(ball_v, cal);
    s->x2 = beam_angle_rad(angle_v, cal);
    s->x3 = 0.0;
    s->x4 = 0.0;
    s->u = 0.0;
    s->u_temp = 0.0;
    return 0;
}

int sf_update(sf_state *s, double ball_v, double angle_v, double *adat_v)
{
    const sf_calibration *c = &s->cal;
    if (!isfinite(ball_v) || !isfinite(angle_v)) return -1;
    /* _measure */
    double x1_k = ball_position_m(ball_v, c);
    double x2_k = beam_angle_rad(angle_v, c);
    /* state_feedback_step: the observer and the law, as printed, left to right */
    double x1 = s->x1, x2 = s->x2, x3 = s->x3, x4 = s->x4, u = s->u;
    double x3_k = 0.9207 * x3 - 0.1601 * x4 - 3.9409 * x1 - 8.0826 * x2 - 0.0055 * u + 4.0 * x1_k +
                  8.0 * x2_k;
    double x4_k = 0.2927 * x3 + 0.7494 * x4 + 14.257 * x1 - 11.945 * x2 + 0.0717 * u - 15.0 * x1_k +
                  12.0 * x2_k;
    double u_temp = -1.0 * (-36.3437 * x1_k + 24.5992 * x2_k - 15.9593 * x3_k + 3.9815 * x4_k);
    if (!isfinite(u_temp)) return -1; /* Python's dac_command_v refuses it (MATLAB would drive NaN) */
    /* _command, then u(k) */
    double adat = clip_command_v(dac_command_v(u_temp, c), c);
    double u_k = motor_volts_from_command(adat, c);
    s->k += 1;
    s->x1 = x1_k;
    s->x2 = x2_k;
    s->x3 = x3_k;
    s->x4 = x4_k;
    s->u = u_k;
    s->u_temp = u_temp;
    *adat_v = adat;
    return 0;
}
