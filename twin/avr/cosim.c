/* The co-simulation's C side: one ATmega firmware image in simavr, stepped cycle by cycle to a target
 * cycle, its ADC inputs set from outside (millivolts at the pins), its SPI DAC frames, resets and stack
 * pointer watched. A program of its own (twin/avr/core.py starts it and speaks to it over its stdin and
 * stdout): whatever a firmware does to simavr — a crash, an exit, text printed by simavr on stdout — ends
 * or disturbs this process, never the twin's. Nothing here knows the rig.
 *
 * A frame is the 16 bits shifted out on SPI while the DAC's chip select is low, latched when it rises (an
 * MCP4921 with LDAC tied low updates its output then). The chip select's port and pin are the board's
 * (twin/avr/boards.py: PB2 on an Uno, PB0 on a Mega 2560), given on the command line. */
#include <simavr/avr_adc.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_spi.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_irq.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define BB_MAX_FRAMES 256
#define BB_MAX_CONVERSIONS 256
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
    uint32_t since_entry[BB_MAX_FRAMES]; /* cycles from the latest interrupt's entry to the frame */
    uint16_t min_sp;
    int bad_frames; /* frames of other than 16 bits */
    uint16_t data_end; /* the first byte above the static data (__heap_start, from the caller): the stack
                          must stay above it */
    uint32_t resets;   /* times the core went back to the reset vector after starting */
    /* The interrupts the core served (simavr's nesting depth going from 0 to 1 and back): how long each
       took, how many, and the cycles the core was awake (running, not asleep). */
    int depth;
    uint64_t entry_cycle;
    int entered; /* an interrupt was entered at least once */
    uint32_t entries;
    uint32_t isr_max_cycles;
    uint64_t isr_cycles;
    uint64_t awake_cycles;
    /* The ADC results the firmware read (its ADCL reads), with the channel and the cycle: what it saw. */
    avr_adc_t *adc_port;
    avr_io_read_t adcl_read;
    void *adcl_param;
    int nconv;
    int conv_dropped;
    uint16_t conv_value[BB_MAX_CONVERSIONS];
    uint8_t conv_channel[BB_MAX_CONVERSIONS];
    uint64_t conv_cycle[BB_MAX_CONVERSIONS];
} bb_cosim;

/* simavr's own ADCL read (which converts and fills ADCH), then the result kept. */
static uint8_t on_adcl(struct avr_t *avr, avr_io_addr_t addr, void *param)
{
    bb_cosim *c = (bb_cosim *)param;
    uint8_t low = c->adcl_read(avr, addr, c->adcl_param);
    if (c->nconv >= BB_MAX_CONVERSIONS) {
        c->conv_dropped++;
        return low;
    }
    c->conv_value[c->nconv] = (uint16_t)(low | (avr->data[c->adc_port->r_adch] << 8));
    c->conv_channel[c->nconv] = avr->data[c->adc_port->r_admux] & 0x0F;
    c->conv_cycle[c->nconv] = avr->cycle;
    c->nconv++;
    return low;
}

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
        if (c->nbytes) c->bad_frames++; /* a select without bytes (the pin set up high) is no frame */
        return;
    }
    if (c->nframes >= BB_MAX_FRAMES) {
        c->dropped++;
        return;
    }
    c->words[c->nframes] = (uint16_t)(c->shift & 0xFFFF);
    c->cycles[c->nframes] = c->avr->cycle;
    c->since_entry[c->nframes] = c->entered ? (uint32_t)(c->avr->cycle - c->entry_cycle) : UINT32_MAX;
    c->nframes++;
}

/* simavr's log: not shown, but its first error (an invalid opcode, a bad address) ends the run, told. */
static char first_error[200];

static void quiet_logger(avr_t *avr, const int level, const char *format, va_list ap)
{
    (void)avr;
    if (level > LOG_ERROR || first_error[0]) return;
    vsnprintf(first_error, sizeof first_error, format, ap);
    if (!first_error[0]) snprintf(first_error, sizeof first_error, "error");
}

/* simavr's default sleeps the host for the time the core sleeps (real-time pacing): the twin paces itself. */
static void no_sleep(avr_t *avr, avr_cycle_count_t how_long)
{
    (void)avr;
    (void)how_long;
}

void bb_free(bb_cosim *c);

/* NULL with a message in err when the image cannot be read, the MCU is unknown or has no such chip-select pin. */
bb_cosim *bb_new(const char *elf, const char *mcu, uint32_t frequency_hz, uint32_t vref_units, char cs_port,
                 int cs_pin, char *err, int errlen)
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
    avr->sleep = no_sleep;
    avr->log = LOG_ERROR; /* errors reach quiet_logger (AVR_LOG filters by this level first) */
    fw->frequency = frequency_hz;
    fw->vcc = fw->avcc = fw->aref = vref_units;
    avr_load_firmware(avr, fw);
    avr->frequency = frequency_hz;
    avr->vcc = avr->avcc = avr->aref = vref_units; /* the ADC's scale: the caller's unit, not mV */
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
    for (avr_io_t *port = avr->io_port; port; port = port->next) {
        if (strcmp(port->kind, "adc") != 0) continue;
        avr_adc_t *adc = (avr_adc_t *)port;
        int slot = AVR_DATA_TO_IO(adc->r_adcl);
        if (slot < 0 || slot >= MAX_IOs || !avr->io[slot].r.c) break;
        c->adc_port = adc;
        c->adcl_read = avr->io[slot].r.c;
        c->adcl_param = avr->io[slot].r.param;
        avr->io[slot].r.c = on_adcl;
        avr->io[slot].r.param = c;
        break;
    }
    avr_irq_t *cs = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(cs_port), IOPORT_IRQ_PIN0 + cs_pin);
    if (!cs) {
        snprintf(err, (size_t)errlen, "%s has no pin P%c%d for the DAC's chip select", mcu, cs_port, cs_pin);
        bb_free(c);
        return NULL;
    }
    avr_irq_register_notify(cs, on_cs, c);
    return c;
}

void bb_free(bb_cosim *c)
{
    if (!c) return;
    avr_terminate(c->avr);
    free(c->avr);
    free(c);
}

static void bb_set_adc(bb_cosim *c, int channel, uint32_t input)
{
    if (channel >= 0 && channel < 8 && c->adc[channel]) avr_raise_irq(c->adc[channel], input);
}

#define BB_STACK_OVERFLOW 100 /* the stack pointer went below the static data */
#define BB_ERROR 101          /* simavr logged an error (first_error says which) */

/* Run to the target cycle (or past it by the last instruction's cycles). Returns simavr's state: running
 * or sleeping (2, 3) to go on; done (6: the firmware stopped, asleep with interrupts off), crashed (7), or
 * BB_STACK_OVERFLOW. */
int bb_run_until(bb_cosim *c, uint64_t cycle)
{
    avr_t *avr = c->avr;
    int state = avr->state;
    while (avr->cycle < cycle) {
        uint32_t pc = avr->pc;
        uint64_t before = avr->cycle;
        state = avr_run(avr);
        if (state == cpu_Running) c->awake_cycles += avr->cycle - before;
        int depth = avr->interrupts.running_ptr;
        if (depth > 0 && c->depth == 0) { /* an interrupt entered from the main program */
            c->entry_cycle = before;
            c->entered = 1;
            c->entries++;
        } else if (depth == 0 && c->depth > 0) { /* its RETI */
            uint64_t took = avr->cycle - c->entry_cycle;
            c->isr_cycles += took;
            if (took > c->isr_max_cycles) c->isr_max_cycles = (uint32_t)(took > UINT32_MAX ? UINT32_MAX : took);
        }
        c->depth = depth;
        if (avr->pc == 0 && pc != 0) c->resets++; /* a watchdog reset, or a jump to the reset vector */
        uint16_t sp = (uint16_t)(avr->data[BB_SPL] | (avr->data[BB_SPL + 1] << 8));
        if (sp < c->min_sp) c->min_sp = sp;
        if (c->data_end && sp < c->data_end) return BB_STACK_OVERFLOW;
        if (first_error[0]) return BB_ERROR;
        if (state == cpu_Done || state == cpu_Crashed) break;
    }
    return state;
}

/* The protocol, little-endian, on stdin and the process's original stdout (simavr's own printf goes to
 * stderr): at start "OK" u16 ramend u16 data_end, or "NO" and a line of text. Then requests:
 *   'A' u8 channel u32 input, in units of V_ref / VREF_UNITS (no answer)
 *   'R' u64 cycle -> i32 state u64 cycle u32 pc u16 min_sp u32 resets i32 bad_frames i32 dropped
 *                    u64 awake_cycles u64 isr_cycles u32 isr_entries u32 isr_max_cycles u8 in_isr u32 n,
 *                    n × (u16 word, u64 cycle, u32 cycles since the latest interrupt's entry, all ones: none),
 *                    u32 m, m × (u16 ADC result, u8 channel, u64 cycle) the firmware read, u32 results dropped,
 *                    u16 length, the first error simavr logged (length bytes, none: 0)
 *   'Q'                                                 (exit) */
static FILE *out;

static int get(void *p, size_t n) { return fread(p, 1, n, stdin) == n; }
static void put(const void *p, size_t n) { fwrite(p, 1, n, out); }

int main(int argc, char **argv)
{
    if (argc != 8 || strlen(argv[6]) != 1 || argv[7][0] < '0' || argv[7][0] > '7' || argv[7][1]) {
        fprintf(stderr, "usage: bbcosim FIRMWARE.elf MCU FREQUENCY_HZ VREF_UNITS DATA_END CS_PORT CS_PIN\n");
        return 2;
    }
    int fd = dup(1);
    if (fd < 0 || dup2(2, 1) < 0) return 2;
    out = fdopen(fd, "wb");
    if (!out) return 2;
    char err[256] = "";
    bb_cosim *c = bb_new(argv[1], argv[2], (uint32_t)strtoul(argv[3], NULL, 10),
                         (uint32_t)strtoul(argv[4], NULL, 10), argv[6][0], argv[7][0] - '0', err, sizeof err);
    if (!c) {
        fprintf(out, "NO%s\n", err);
        fflush(out);
        return 1;
    }
    c->data_end = (uint16_t)strtoul(argv[5], NULL, 0); /* 0: not known, not watched */
    put("OK", 2);
    put(&c->avr->ramend, 2);
    put(&c->data_end, 2);
    fflush(out);
    for (;;) {
        char op;
        if (!get(&op, 1) || op == 'Q') break;
        if (op == 'A') {
            uint8_t channel;
            uint32_t input;
            if (!get(&channel, 1) || !get(&input, 4)) break;
            bb_set_adc(c, channel, input);
        } else if (op == 'R') {
            uint64_t target;
            if (!get(&target, 8)) break;
            int32_t state = bb_run_until(c, target);
            uint64_t now = c->avr->cycle;
            uint32_t pc = c->avr->pc, n = (uint32_t)c->nframes;
            int32_t bad = c->bad_frames, dropped = c->dropped;
            put(&state, 4);
            put(&now, 8);
            put(&pc, 4);
            put(&c->min_sp, 2);
            put(&c->resets, 4);
            put(&bad, 4);
            put(&dropped, 4);
            put(&c->awake_cycles, 8);
            put(&c->isr_cycles, 8);
            put(&c->entries, 4);
            put(&c->isr_max_cycles, 4);
            uint8_t in_isr = c->depth > 0;
            put(&in_isr, 1);
            put(&n, 4);
            for (uint32_t i = 0; i < n; i++) {
                put(&c->words[i], 2);
                put(&c->cycles[i], 8);
                put(&c->since_entry[i], 4);
            }
            c->nframes = 0;
            uint32_t m = (uint32_t)c->nconv, conv_dropped = (uint32_t)c->conv_dropped;
            put(&m, 4);
            for (uint32_t i = 0; i < m; i++) {
                put(&c->conv_value[i], 2);
                put(&c->conv_channel[i], 1);
                put(&c->conv_cycle[i], 8);
            }
            put(&conv_dropped, 4);
            c->nconv = 0;
            c->conv_dropped = 0;
            uint16_t length = (uint16_t)strlen(first_error);
            put(&length, 2);
            put(first_error, length);
            fflush(out);
        } else {
            break;
        }
    }
    bb_free(c);
    return 0;
}
