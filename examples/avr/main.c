/* The appendix A state feedback on an ATmega328P at 16 MHz: the same law source as the PC client
 * (../c/appendix_sf.c; avr-gcc's double is IEEE binary32, so here the law runs in single precision).
 *
 * Every 20 ms (Timer1 compare interrupt) the firmware reads both sensor channels (IO_SAMPLES_PER_CHANNEL
 * conversions each, averaged), turns the counts back into the rig's volts through the front end, runs the
 * law and writes the command to the MCP4921 DAC over SPI. The first period starts the law from the held
 * rig's readings (sf_start) and holds the zero command; each later one drives (sf_update). Between
 * interrupts the core sleeps (idle). Pins: ADC0 ball, ADC1 angle; SPI MOSI PB3, SCK PB5, DAC chip select
 * PB2 (SS, an output). */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <stdint.h>

#include "appendix_sf.h"
#include "rig.h"
#include "rig_io.h"

static sf_state law;
static uint8_t started;

static uint16_t adc_read(uint8_t channel)
{
    ADMUX = (uint8_t)((1 << REFS0) | channel); /* AVcc reference, right-adjusted */
    ADCSRA |= (1 << ADSC);
    while (ADCSRA & (1 << ADSC)) {
    }
    return ADC;
}

/* The mean of the channel's conversions, in the rig's volts (rig_io.h). */
static double channel_v(uint8_t channel)
{
    uint16_t sum = 0;
    for (uint8_t i = 0; i < IO_SAMPLES_PER_CHANNEL; i++) sum += adc_read(channel);
    return io_signal_v(sum);
}

static void dac_write(double command_v)
{
    uint16_t frame = io_dac_frame(command_v);
    PORTB &= (uint8_t)~(1 << PB2);
    SPDR = (uint8_t)(frame >> 8);
    while (!(SPSR & (1 << SPIF))) {
    }
    SPDR = (uint8_t)(frame & 0xFF);
    while (!(SPSR & (1 << SPIF))) {
    }
    PORTB |= (1 << PB2); /* the DAC's output follows on chip select's rising edge (LDAC tied low) */
}

ISR(TIMER1_COMPA_vect)
{
    double ball_v = channel_v(IO_BALL_CHANNEL);
    double angle_v = channel_v(IO_ANGLE_CHANNEL);
    double command_v = RIG_COMMAND_ZERO_V;
    if (!started) {
        static const sf_calibration cal = RIG_SF_CALIBRATION;
        started = sf_start(&law, &cal, ball_v, angle_v) == 0;
    } else if (sf_update(&law, ball_v, angle_v, &command_v) != 0) {
        command_v = RIG_COMMAND_ZERO_V; /* a reading the law refuses: the motor off for this period */
    }
    dac_write(command_v);
}

int main(void)
{
    DDRB |= (1 << PB2) | (1 << PB3) | (1 << PB5);
    PORTB |= (1 << PB2);
    SPCR = (1 << SPE) | (1 << MSTR);
    SPSR = (1 << SPI2X); /* SCK = F_CPU / 2 */
    ADCSRA = (1 << ADEN) | (1 << ADPS2) | (1 << ADPS1) | (1 << ADPS0); /* ADC clock F_CPU / 128 */
    dac_write(RIG_COMMAND_ZERO_V);
    TCCR1A = 0;
    TCCR1B = (1 << WGM12) | (1 << CS11) | (1 << CS10); /* CTC, F_CPU / 64 */
    OCR1A = (uint16_t)(F_CPU / 64UL * 20UL / 1000UL - 1UL); /* RIG_PERIOD_S */
    TIMSK1 = (1 << OCIE1A);
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();
    for (;;) sleep_mode();
}
