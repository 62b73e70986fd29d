/* What the firmware knows of its rig: the rig software's calibration (the thesis's values, as
 * twin.parameters.SoftwareCalibration holds them) and the board's analog front end and output
 * (twin.parameters.McuIo). tests/test_avr.py checks every number here against the twin's parameters, so a
 * change on one side and not the other fails there. */
#ifndef RIG_H
#define RIG_H

/* eq 6.3.1, eq 6.2.10, §6.4 */
#define RIG_BALL_GAIN_M_PER_V 0.0693
#define RIG_BALL_OFFSET_M 0.0018
#define RIG_ANGLE_GAIN_DEG_PER_V 143.22657649
#define RIG_ANGLE_REFERENCE_V 5.002
#define RIG_ANGLE_REFERENCE_MOTOR_DEG 718.59375
#define RIG_ANGLE_GEAR_RATIO 7.0
#define RIG_SOFTWARE_PI 3.141592654
#define RIG_COMMAND_GAIN_V_PER_V 9.6
#define RIG_COMMAND_ZERO_V 2.5
#define RIG_COMMAND_LOW_V 1.25
#define RIG_COMMAND_HIGH_V 3.75

/* The law's calibration (../c/appendix_sf.h), in its field order. */
#define RIG_SF_CALIBRATION                                                                                     \
    {                                                                                                          \
        RIG_BALL_GAIN_M_PER_V, RIG_BALL_OFFSET_M, RIG_ANGLE_GAIN_DEG_PER_V, RIG_ANGLE_REFERENCE_V,            \
            RIG_ANGLE_REFERENCE_MOTOR_DEG, RIG_ANGLE_GEAR_RATIO, RIG_SOFTWARE_PI, RIG_COMMAND_GAIN_V_PER_V,   \
            RIG_COMMAND_ZERO_V, RIG_COMMAND_LOW_V, RIG_COMMAND_HIGH_V                                         \
    }

/* The period: 20 ms (the rig's 50 Hz), from Timer1 in CTC mode at F_CPU / 64. */
#define RIG_PERIOD_S 0.02

/* The analog front end: each ±5 V sensor signal through a divider onto 0…5 V at the pin,
 * pin = offset + gain * signal, read by the 10-bit ADC against AVcc = 5 V. */
#define IO_INPUT_GAIN_V_PER_V 0.5
#define IO_INPUT_OFFSET_V 2.5
#define IO_ADC_REFERENCE_V 5.0
#define IO_ADC_BITS 10
#define IO_BALL_CHANNEL 0
#define IO_ANGLE_CHANNEL 1
/* Conversions averaged per channel each period (the firmware author's choice: 8 × 104 µs). */
#define IO_SAMPLES_PER_CHANNEL 8

/* The output: an MCP4921 12-bit SPI DAC against a 5 V reference into the amplifier's 0…5 V command. */
#define IO_DAC_BITS 12
#define IO_DAC_REFERENCE_V 5.0

#endif
