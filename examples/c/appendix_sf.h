/* The state feedback of appendix A ("d_cb_state_feedback", control == 5) with its observer, as the rig
 * ran it: a port of controllers/appendix.py:AppendixStateFeedback and the conversions of
 * twin/converters.py, statement by statement in the same floating-point order, so that (compiled
 * without contraction into FMA, see the Makefile) it computes the Python port's doubles bit for bit.
 *
 * The calibration is not typed in: it arrives in the server's CONFIG (docs/protocol.md).
 */
#ifndef APPENDIX_SF_H
#define APPENDIX_SF_H

/* The rig software's conversions (twin.parameters.SoftwareCalibration). */
typedef struct {
    double ball_gain_m_per_v, ball_offset_m;
    double angle_gain_deg_per_v, angle_reference_v, angle_reference_motor_deg, angle_gear_ratio;
    double software_pi;
    double command_gain_v_per_v, command_zero_v, command_low_v, command_high_v;
} sf_calibration;

/* The callback's memory: the values at k - 1 it reads back, and what it logs at k. */
typedef struct {
    sf_calibration cal;
    long k;                /* the tick index: 1 at start */
    double x1, x2, x3, x4; /* x1(k) m, x2(k) rad, x3(k) m/s, x4(k) rad/s: the estimate */
    double u;              /* u(k) = (adat - 2.5)*9.6: the motor volts fed back to the observer */
    double u_temp;         /* the computed motor volts before the command limits (uhesap) */
} sf_state;

/* control == 1 / 4 (Start, Clear Buffer): x1(1), x2(1) from the held rig's block, x3 = x4 = u = 0.
 * Returns 0, or -1 when a volt value is not finite (nothing is changed then). */
int sf_start(sf_state *s, const sf_calibration *cal, double ball_v, double angle_v);

/* control == 5 (Drive Motor): one block in, the clipped DAC command out (*adat_v).
 * Returns 0, or -1 when a volt value or the computed command is not finite (the state is kept). */
int sf_update(sf_state *s, double ball_v, double angle_v, double *adat_v);

#endif
