/* The co-simulation's C side: one ATmega firmware image in simavr, stepped cycle by cycle to a target
 * cycle, its ADC inputs set from outside (millivolts at the pins), its SPI DAC frames and its stack pointer
 * watched. Loaded by twin/avr/core.py through ctypes; nothing here knows the rig.
 *
 * A frame is the 16 bits shifted out on SPI while the DAC's chip select (PB2) is low, latched when it rises
 * (an MCP4921 with LDAC tied low updates its output then). */
#include <simavr/avr_adc.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_spi.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_irq.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define BB_MAX_FRAMES 256
#define BB_SPL 0x5D /* SPL in data space (I/O 0x3D + 0x20) */

typedef struct {
    avr_t *avr;
    avr_irq_t *adc[8];
    int cs_low;
    int nbytes;
    uint32_t shift;
    int nframes;
    int dropped;
    uint16_t words[BB_MAX_FRAMES];
    uint64_t cycles[BB_MAX_FRAMES];
    uint16_t min_sp;
    int bad_frames; /* frames of other than 16 bits */
} bb_cosim;

static void on_spi(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    bb_cosim *c = (bb_cosim *)param;
    if (!c->cs_low) return;
    c->shift = (c->shift << 8) | (value & 0xFF);
    c->nbytes++;
}

static void on_cs(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    bb_cosim *c = (bb_cosim *)param;
    if (!value) {
        c->cs_low = 1;
        c->nbytes = 0;
        c->shift = 0;
        return;
    }
    if (!c->cs_low) return;
    c->cs_low = 0;
    if (c->nbytes != 2) {
        c->bad_frames++;
        return;
    }
    if (c->nframes >= BB_MAX_FRAMES) {
        c->dropped++;
        return;
    }
    c->words[c->nframes] = (uint16_t)(c->shift & 0xFFFF);
    c->cycles[c->nframes] = c->avr->cycle;
    c->nframes++;
}

static void quiet_logger(avr_t *avr, const int level, const char *format, va_list ap)
{
    (void)avr;
    (void)level;
    (void)format;
    (void)ap;
}

/* NULL with a message in err when the image cannot be read or the MCU is unknown. */
bb_cosim *bb_new(const char *elf, const char *mcu, uint32_t frequency_hz, uint32_t vcc_mv, char *err,
                 int errlen)
{
    avr_global_logger_set(quiet_logger);
    /* Room beyond the header's struct: the reader fills what the library was built with. */
    elf_firmware_t *fw = calloc(1, sizeof(elf_firmware_t) + 4096);
    if (!fw) {
        snprintf(err, (size_t)errlen, "out of memory");
        return NULL;
    }
    if (elf_read_firmware(elf, fw) != 0) {
        snprintf(err, (size_t)errlen, "not an AVR ELF image simavr can read");
        free(fw);
        return NULL;
    }
    avr_t *avr = avr_make_mcu_by_name(mcu);
    if (!avr) {
        snprintf(err, (size_t)errlen, "simavr has no MCU named %s", mcu);
        free(fw);
        return NULL;
    }
    avr_init(avr);
    fw->frequency = frequency_hz;
    fw->vcc = fw->avcc = fw->aref = vcc_mv;
    avr_load_firmware(avr, fw);
    avr->frequency = frequency_hz;
    avr->vcc = avr->avcc = avr->aref = vcc_mv;
    free(fw);
    bb_cosim *c = calloc(1, sizeof(bb_cosim));
    if (!c) {
        snprintf(err, (size_t)errlen, "out of memory");
        return NULL;
    }
    c->avr = avr;
    c->min_sp = 0xFFFF;
    for (int i = 0; i < 8; i++) c->adc[i] = avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + i);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_SPI_GETIRQ(0), SPI_IRQ_OUTPUT), on_spi, c);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_PIN2), on_cs, c);
    return c;
}

void bb_free(bb_cosim *c)
{
    if (!c) return;
    avr_terminate(c->avr);
    free(c->avr);
    free(c);
}

void bb_set_adc_mv(bb_cosim *c, int channel, uint32_t mv)
{
    if (channel >= 0 && channel < 8 && c->adc[channel]) avr_raise_irq(c->adc[channel], mv);
}

/* Run to the target cycle (or past it by the last instruction's cycles). Returns simavr's state: running
 * or sleeping (2, 3) to go on; done (6: the firmware stopped, asleep with interrupts off) or crashed (7). */
int bb_run_until(bb_cosim *c, uint64_t cycle)
{
    avr_t *avr = c->avr;
    int state = avr->state;
    while (avr->cycle < cycle) {
        state = avr_run(avr);
        uint16_t sp = (uint16_t)(avr->data[BB_SPL] | (avr->data[BB_SPL + 1] << 8));
        if (sp < c->min_sp) c->min_sp = sp;
        if (state == cpu_Done || state == cpu_Crashed) break;
    }
    return state;
}

uint64_t bb_cycle(const bb_cosim *c) { return c->avr->cycle; }
uint32_t bb_pc(const bb_cosim *c) { return c->avr->pc; }
uint16_t bb_min_sp(const bb_cosim *c) { return c->min_sp; }
uint16_t bb_ramend(const bb_cosim *c) { return c->avr->ramend; }
int bb_bad_frames(const bb_cosim *c) { return c->bad_frames; }

/* The frames latched since the last call (at most max; the rest are kept for the next call). */
int bb_take_frames(bb_cosim *c, uint16_t *words, uint64_t *cycles, int max)
{
    int n = c->nframes < max ? c->nframes : max;
    memcpy(words, c->words, (size_t)n * sizeof(uint16_t));
    memcpy(cycles, c->cycles, (size_t)n * sizeof(uint64_t));
    memmove(c->words, c->words + n, (size_t)(c->nframes - n) * sizeof(uint16_t));
    memmove(c->cycles, c->cycles + n, (size_t)(c->nframes - n) * sizeof(uint64_t));
    c->nframes -= n;
    return n;
}
