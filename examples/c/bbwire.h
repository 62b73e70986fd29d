/* bbwire: the frames of protocol 1 (docs/protocol.md), packed and unpacked byte by byte.
 *
 * Every field is little-endian at a fixed offset; nothing here depends on the host's byte order,
 * struct layout or padding (no struct is ever copied onto the wire). Plain C99.
 */
#ifndef BBWIRE_H
#define BBWIRE_H

#include <stddef.h>
#include <stdint.h>

#define BB_VERSION 1u
#define BB_HEADER_LEN 16u
#define BB_MAX_FRAME_LEN 200u /* CONFIG, the longest */

enum bb_type { BB_HELLO = 1, BB_CONFIG = 2, BB_SAMPLE = 3, BB_COMMAND = 4, BB_STOP = 5 };

enum bb_role { BB_ROLE_REFUSED = 0, BB_ROLE_CONTROL = 1, BB_ROLE_OBSERVE = 2 };

enum bb_mode { BB_MODE_LOCKSTEP = 1, BB_MODE_REALTIME = 2 };

/* SAMPLE flags */
#define BB_FLAG_HELD 0x1u
#define BB_FLAG_BALL_LOST 0x2u
#define BB_FLAG_WATCHDOG 0x4u
#define BB_FLAG_LATE 0x8u
#define BB_FLAG_LAST 0x10u
#define BB_FLAG_REFUSED 0x20u /* lock-step, on a repeated sample: its COMMAND was refused (not finite, out of range) */

enum bb_stop_reason {
    BB_STOP_DONE = 0,
    BB_STOP_CLIENT_QUIT = 1,
    BB_STOP_BALL_LOST = 2,
    BB_STOP_ERROR = 3,
    BB_STOP_SHUTDOWN = 4
};

/* What bb_decode reports. */
enum bb_status {
    BB_OK = 0,
    BB_ERR_SHORT = -1,   /* fewer bytes than a header, or than the type's length */
    BB_ERR_MAGIC = -2,   /* not B B T W */
    BB_ERR_VERSION = -3, /* not protocol 1 */
    BB_ERR_TYPE = -4,    /* not 1..5 */
    BB_ERR_LENGTH = -5,  /* the length field, or the bytes given, differ from the type's length */
    BB_ERR_CRC = -6      /* the CRC does not match */
};

typedef struct {
    uint8_t role;
    char client[33]; /* 32 bytes on the wire, NUL-terminated here */
} bb_hello;

typedef struct {
    uint8_t role, mode, ball_block, angle_block;
    double period_s, sample_rate_hz;
    uint32_t watchdog_periods;
    double dac_min_v, dac_max_v, zero_command_v;
    double ball_gain_m_per_v, ball_offset_m;
    double angle_gain_deg_per_v, angle_reference_v, angle_reference_motor_deg, angle_gear_ratio;
    double software_pi;
    double command_gain_v_per_v, command_zero_v, command_low_v, command_high_v;
    char rig[41]; /* 40 bytes on the wire, NUL-terminated here */
} bb_config;

typedef struct {
    double time_s, ball_v, angle_v;
    uint32_t flags, applied_seq;
} bb_sample;

typedef struct {
    double dac_v;
} bb_command;

typedef struct {
    uint32_t reason;
} bb_stop;

typedef struct {
    uint8_t type; /* enum bb_type */
    uint32_t seq, session;
    union {
        bb_hello hello;
        bb_config config;
        bb_sample sample;
        bb_command command;
        bb_stop stop;
    } u;
} bb_frame;

/* CRC-32/ISO-HDLC (zlib's crc32): check value of "123456789" is 0xCBF43926. */
uint32_t bb_crc32(const uint8_t *data, size_t len);

/* The frame length of a type (header and CRC included), 0 for an unknown type. */
size_t bb_frame_length(unsigned type);

/* Packs f into buf (at least bb_frame_length(f->type) bytes); returns the length, 0 for an unknown type
 * or a buffer too small. Pads are zero; text is NUL-padded (cut at its field's size). */
size_t bb_encode(const bb_frame *f, uint8_t *buf, size_t cap);

/* Checks and unpacks the len bytes of one frame; returns BB_OK or a negative enum bb_status. */
int bb_decode(const uint8_t *buf, size_t len, bb_frame *f);

/* A short text for a bb_decode status. */
const char *bb_status_text(int status);

#endif
