/* The firmware's arithmetic between the pins and the law: ADC counts to the rig's volts, the command to the
 * DAC's word. Shared by main.c and the host build of the law that the tests compare the firmware with
 * (tests/test_avr.py), so both compute the same floats. `double` is the target's: IEEE binary32 on the AVR
 * (and on the host build, compiled with -Ddouble=float -fsingle-precision-constant). */
#ifndef RIG_IO_H
#define RIG_IO_H

#include <stdint.h>

#include "rig.h"

/* The rig's volts for the sum of IO_SAMPLES_PER_CHANNEL conversions: their mean count's centre
 * (+ half a count), in volts at the pin, back through the divider. */
static inline double io_signal_v(uint16_t sum)
{
    double count = (double)sum / IO_SAMPLES_PER_CHANNEL + 0.5;
    double pin_v = count * (IO_ADC_REFERENCE_V / (double)(1UL << IO_ADC_BITS));
    return (pin_v - IO_INPUT_OFFSET_V) / IO_INPUT_GAIN_V_PER_V;
}

/* The MCP4921 frame for a command in volts: the nearest code within 0…4095, DAC A, unbuffered, gain 1,
 * active. */
static inline uint16_t io_dac_frame(double command_v)
{
    double code = command_v * ((double)(1UL << IO_DAC_BITS) / IO_DAC_REFERENCE_V) + 0.5;
    uint16_t word = code <= 0.0 ? 0 : (code >= 4095.0 ? 4095 : (uint16_t)code);
    return (uint16_t)(0x3000u | word);
}

#endif
