/* bbwire: the frames of protocol 1 (docs/protocol.md). See bbwire.h. */
#include "bbwire.h"

#include <string.h>

/* f64 fields are IEEE 754 binary64: refuse to build where double is narrower (e.g. avr-gcc's default). */
typedef char bb_double_is_binary64[(sizeof(double) == 8 && sizeof(uint64_t) == 8) ? 1 : -1];

static uint32_t crc_table[256];
static int crc_table_ready = 0;

static void crc_init(void)
{
    /* The reflected polynomial 0xEDB88320 (0x04C11DB7 bit-reversed), one table entry per byte. */
    for (uint32_t n = 0; n < 256; n++) {
        uint32_t c = n;
        for (int b = 0; b < 8; b++) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        crc_table[n] = c;
    }
    crc_table_ready = 1;
}

uint32_t bb_crc32(const uint8_t *data, size_t len)
{
    if (!crc_table_ready) crc_init();
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < len; i++) c = crc_table[(c ^ data[i]) & 0xFFu] ^ (c >> 8);
    return c ^ 0xFFFFFFFFu;
}

size_t bb_frame_length(unsigned type)
{
    switch (type) {
    case BB_HELLO: return 56;
    case BB_CONFIG: return 200;
    case BB_SAMPLE: return 56;
    case BB_COMMAND: return 32;
    case BB_STOP: return 24;
    default: return 0;
    }
}

/* --- little-endian packing, one byte at a time ------------------------------------------------ */

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xFFu);
    p[1] = (uint8_t)(v >> 8);
}

static void put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)((v >> (8 * i)) & 0xFFu);
}

static void put_f64(uint8_t *p, double d)
{
    uint64_t v;
    memcpy(&v, &d, sizeof v); /* the double's IEEE 754 bits as an integer (C99's only portable way) */
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)((v >> (8 * i)) & 0xFFu);
}

static void put_text(uint8_t *p, const char *s, size_t n)
{
    size_t i = 0;
    for (; i < n && s[i] != '\0'; i++) p[i] = (uint8_t)s[i];
    for (; i < n; i++) p[i] = 0;
}

static uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }

static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static double get_f64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = (v << 8) | p[i];
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

static void get_text(char *out, const uint8_t *p, size_t n)
{
    size_t i = 0;
    for (; i < n && p[i] != 0; i++) out[i] = (char)p[i];
    out[i] = '\0';
}

size_t bb_encode(const bb_frame *f, uint8_t *buf, size_t cap)
{
    size_t len = bb_frame_length(f->type);
    if (len == 0 || cap < len) return 0;
    memset(buf, 0, len);
    buf[0] = 'B';
    buf[1] = 'B';
    buf[2] = 'T';
    buf[3] = 'W';
    buf[4] = BB_VERSION;
    buf[5] = f->type;
    put_u16(buf + 6, (uint16_t)len);
    put_u32(buf + 8, f->seq);
    put_u32(buf + 12, f->session);
    switch (f->type) {
    case BB_HELLO:
        buf[16] = f->u.hello.role;
        put_text(buf + 20, f->u.hello.client, 32);
        break;
    case BB_CONFIG: {
        const bb_config *c = &f->u.config;
        buf[16] = c->role;
        buf[17] = c->mode;
        buf[18] = c->ball_block;
        buf[19] = c->angle_block;
        put_f64(buf + 20, c->period_s);
        put_f64(buf + 28, c->sample_rate_hz);
        put_u32(buf + 36, c->watchdog_periods);
        put_f64(buf + 44, c->dac_min_v);
        put_f64(buf + 52, c->dac_max_v);
        put_f64(buf + 60, c->zero_command_v);
        put_f64(buf + 68, c->ball_gain_m_per_v);
        put_f64(buf + 76, c->ball_offset_m);
        put_f64(buf + 84, c->angle_gain_deg_per_v);
        put_f64(buf + 92, c->angle_reference_v);
        put_f64(buf + 100, c->angle_reference_motor_deg);
        put_f64(buf + 108, c->angle_gear_ratio);
        put_f64(buf + 116, c->software_pi);
        put_f64(buf + 124, c->command_gain_v_per_v);
        put_f64(buf + 132, c->command_zero_v);
        put_f64(buf + 140, c->command_low_v);
        put_f64(buf + 148, c->command_high_v);
        put_text(buf + 156, c->rig, 40);
        break;
    }
    case BB_SAMPLE:
        put_f64(buf + 16, f->u.sample.time_s);
        put_f64(buf + 24, f->u.sample.ball_v);
        put_f64(buf + 32, f->u.sample.angle_v);
        put_u32(buf + 40, f->u.sample.flags);
        put_u32(buf + 44, f->u.sample.applied_seq);
        break;
    case BB_COMMAND:
        put_f64(buf + 16, f->u.command.dac_v);
        break;
    case BB_STOP:
        put_u32(buf + 16, f->u.stop.reason);
        break;
    default:
        return 0;
    }
    put_u32(buf + len - 4, bb_crc32(buf, len - 4));
    return len;
}

int bb_decode(const uint8_t *buf, size_t len, bb_frame *f)
{
    if (len < BB_HEADER_LEN) return BB_ERR_SHORT;
    if (buf[0] != 'B' || buf[1] != 'B' || buf[2] != 'T' || buf[3] != 'W') return BB_ERR_MAGIC;
    if (buf[4] != BB_VERSION) return BB_ERR_VERSION;
    size_t want = bb_frame_length(buf[5]);
    if (want == 0) return BB_ERR_TYPE;
    if (get_u16(buf + 6) != want || len != want) return BB_ERR_LENGTH;
    if (get_u32(buf + want - 4) != bb_crc32(buf, want - 4)) return BB_ERR_CRC;
    memset(f, 0, sizeof *f);
    f->type = buf[5];
    f->seq = get_u32(buf + 8);
    f->session = get_u32(buf + 12);
    switch (f->type) {
    case BB_HELLO:
        f->u.hello.role = buf[16];
        get_text(f->u.hello.client, buf + 20, 32);
        break;
    case BB_CONFIG: {
        bb_config *c = &f->u.config;
        c->role = buf[16];
        c->mode = buf[17];
        c->ball_block = buf[18];
        c->angle_block = buf[19];
        c->period_s = get_f64(buf + 20);
        c->sample_rate_hz = get_f64(buf + 28);
        c->watchdog_periods = get_u32(buf + 36);
        c->dac_min_v = get_f64(buf + 44);
        c->dac_max_v = get_f64(buf + 52);
        c->zero_command_v = get_f64(buf + 60);
        c->ball_gain_m_per_v = get_f64(buf + 68);
        c->ball_offset_m = get_f64(buf + 76);
        c->angle_gain_deg_per_v = get_f64(buf + 84);
        c->angle_reference_v = get_f64(buf + 92);
        c->angle_reference_motor_deg = get_f64(buf + 100);
        c->angle_gear_ratio = get_f64(buf + 108);
        c->software_pi = get_f64(buf + 116);
        c->command_gain_v_per_v = get_f64(buf + 124);
        c->command_zero_v = get_f64(buf + 132);
        c->command_low_v = get_f64(buf + 140);
        c->command_high_v = get_f64(buf + 148);
        get_text(c->rig, buf + 156, 40);
        break;
    }
    case BB_SAMPLE:
        f->u.sample.time_s = get_f64(buf + 16);
        f->u.sample.ball_v = get_f64(buf + 24);
        f->u.sample.angle_v = get_f64(buf + 32);
        f->u.sample.flags = get_u32(buf + 40);
        f->u.sample.applied_seq = get_u32(buf + 44);
        break;
    case BB_COMMAND:
        f->u.command.dac_v = get_f64(buf + 16);
        break;
    case BB_STOP:
        f->u.stop.reason = get_u32(buf + 16);
        break;
    default:
        return BB_ERR_TYPE;
    }
    return BB_OK;
}

const char *bb_status_text(int status)
{
    switch (status) {
    case BB_OK: return "ok";
    case BB_ERR_SHORT: return "short frame";
    case BB_ERR_MAGIC: return "bad magic";
    case BB_ERR_VERSION: return "unsupported version";
    case BB_ERR_TYPE: return "unknown type";
    case BB_ERR_LENGTH: return "wrong length";
    case BB_ERR_CRC: return "bad crc";
    default: return "unknown status";
    }
}
