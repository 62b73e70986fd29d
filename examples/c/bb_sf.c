/* bb_sf: the appendix A state feedback as a client of a served rig (docs/protocol.md).
 *
 *   bb_sf udp HOST PORT [options]   HELLO, CONFIG, then SAMPLE -> COMMAND until STOP (or the last sample)
 *   bb_sf pipe [options]            the same frames over stdin/stdout, back to back (no network)
 *   bb_sf selftest                  decode the frames on stdin, print their fields and re-encoded bytes
 *   bb_sf crc                       print the CRC-32 of stdin
 * options: --timeout S (default 10: the longest wait for CONFIG, for any frame of the session, and for the
 *          server to move on from a sample it repeats after our answer), --wait-start S (default 0: no
 *          limit; how long the server may hold the session once we acknowledged its held sample, repeating
 *          it: the live view holds it until a browser connects), --trace PATH (one line per sample:
 *          seq, x1..x4, u, u_temp, command as C99 hex floats; "-" is stderr; with several sessions their
 *          lines follow each other, each session's from seq 0), --name NAME (HELLO's client),
 *          --sessions N (default 1: N sessions one after the other, a fresh controller each, as a served
 *          job's runs come: ballbeam sweep/montecarlo/validate --serve; 0: until no CONFIG answers HELLO
 *          within --timeout).
 *
 * Exit status: 0 every session ended as the server said it would (STOP done, or the last sample
 * answered); 1 a session failed (refused, a server that went silent, a ball lost, a bad CONFIG, a
 * non-finite value; the next session is still run unless the server refused us or is gone); 2 a usage
 * error; 128 + the signal after SIGINT/SIGTERM (having sent STOP 1, client quit).
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <math.h>
#include <netdb.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <time.h>
#include <unistd.h>

#include "appendix_sf.h"
#include "bbwire.h"

#define HELLO_REPEAT_MS 200 /* docs/protocol.md: a client repeats HELLO until it receives CONFIG */
#define PERIOD_S 0.02       /* the period the observer's matrices were discretised for (Table 6.4) */
#define PERIOD_TOLERANCE_S 1e-12

/* --- transports: one frame per datagram, or a byte stream of frames ------------------------------ */

enum { RX_FRAME = 1, RX_TIMEOUT = 0, RX_EOF = 2, RX_QUIT = 3 }; /* negative: a rejected frame */

/* run_session's results besides 0 (ended as the server said), 1 (failed) and 128 + a signal */
enum { SESSION_NO_CONFIG = 3, SESSION_FATAL = 4 }; /* no server within the timeout; no further session */

/* SIGINT/SIGTERM: the session ends with STOP 1 (client quit) rather than a silent controller. */
static volatile sig_atomic_t quit_signal = 0;

static void on_quit_signal(int signo) { quit_signal = signo; }

typedef struct {
    int udp;        /* 1: a connected UDP socket; 0: the stdin/stdout stream */
    int fd_in, fd_out;
    uint8_t buf[4 * BB_MAX_FRAME_LEN];
    size_t have;    /* stream bytes buffered */
    int eof;
    unsigned long skipped_bytes; /* stream bytes dropped while searching for the magic */
} transport;

static int send_frame(transport *t, const uint8_t *frame, size_t len)
{
    if (t->udp) {
        /* a refused or lost datagram is the protocol's business (repeats, timeouts), not a crash */
        return send(t->fd_out, frame, len, 0) == (ssize_t)len ? 0 : -1;
    }
    size_t done = 0;
    while (done < len) {
        ssize_t n = write(t->fd_out, frame + done, len - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return -1;
        done += (size_t)n;
    }
    return 0;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Waits at most timeout_ms for the input to be readable: 1 readable, 0 not. */
static int wait_readable(int fd, int timeout_ms)
{
    struct pollfd p = {fd, POLLIN, 0};
    for (;;) {
        int r = poll(&p, 1, timeout_ms);
        if (r < 0 && errno == EINTR && !quit_signal) continue;
        return r > 0;
    }
}

/* The next frame candidate from the stream: the bytes of one whole frame of a known type (checked
 * here), or a rejected candidate after which the search goes on one byte further. */
static int stream_next(transport *t, uint8_t *frame, size_t *len, int timeout_ms)
{
    double deadline = now_s() + timeout_ms / 1000.0;
    for (;;) {
        if (quit_signal) return RX_QUIT;
        /* drop bytes until the buffer starts with (a prefix of) the magic */
        size_t i = 0;
        while (i < t->have) {
            size_t n = t->have - i < 4 ? t->have - i : 4;
            if (memcmp(t->buf + i, "BBTW", n) == 0) break;
            i++;
        }
        if (i > 0) {
            t->skipped_bytes += i;
            memmove(t->buf, t->buf + i, t->have - i);
            t->have -= i;
        }
        if (t->have >= BB_HEADER_LEN) {
            size_t want = bb_frame_length(t->buf[5]);
            int status = BB_OK;
            if (t->buf[4] != BB_VERSION) status = BB_ERR_VERSION;
            else if (want == 0) status = BB_ERR_TYPE;
            else if ((size_t)(t->buf[6] | (t->buf[7] << 8)) != want) status = BB_ERR_LENGTH;
            if (status == BB_OK && t->have >= want) {
                memcpy(frame, t->buf, want);
                *len = want;
                memmove(t->buf, t->buf + want, t->have - want);
                t->have -= want;
                return RX_FRAME;
            }
            if (status != BB_OK) {
                memmove(t->buf, t->buf + 1, t->have - 1);
                t->have -= 1;
                t->skipped_bytes += 1;
                return status;
            }
        }
        if (t->eof) return RX_EOF;
        int left_ms = (int)((deadline - now_s()) * 1000.0);
        if (left_ms < 0 || !wait_readable(t->fd_in, left_ms)) return quit_signal ? RX_QUIT : RX_TIMEOUT;
        ssize_t n = read(t->fd_in, t->buf + t->have, sizeof t->buf - t->have);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) t->eof = 1;
        else t->have += (size_t)n;
    }
}

static int receive(transport *t, uint8_t *frame, size_t *len, int timeout_ms)
{
    if (!t->udp) return stream_next(t, frame, len, timeout_ms);
    double deadline = now_s() + timeout_ms / 1000.0;
    for (;;) {
        if (quit_signal) return RX_QUIT;
        int left_ms = (int)((deadline - now_s()) * 1000.0);
        if (left_ms < 0 || !wait_readable(t->fd_in, left_ms)) return quit_signal ? RX_QUIT : RX_TIMEOUT;
        uint8_t big[BB_MAX_FRAME_LEN + 1]; /* one byte more: an oversized datagram is seen as such */
        ssize_t n = recv(t->fd_in, big, sizeof big, 0);
        if (n < 0) continue; /* EINTR, or ECONNREFUSED from a server not (yet) listening */
        if ((size_t)n > BB_MAX_FRAME_LEN) return BB_ERR_LENGTH;
        memcpy(frame, big, (size_t)n);
        *len = (size_t)n;
        return RX_FRAME;
    }
}

static int open_udp(transport *t, const char *host, const char *port)
{
    struct addrinfo hints, *res = NULL;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    int rc = getaddrinfo(host, port, &hints, &res);
    if (rc != 0) {
        fprintf(stderr, "bb_sf: udp %s %s: %s\n", host, port, gai_strerror(rc));
        return -1;
    }
    int fd = -1;
    for (struct addrinfo *a = res; a != NULL; a = a->ai_next) {
        fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
        if (fd < 0) continue;
        if (connect(fd, a->ai_addr, a->ai_addrlen) == 0) break; /* only the server's datagrams */
        close(fd);
        fd = -1;
    }
    freeaddrinfo(res);
    if (fd < 0) {
        fprintf(stderr, "bb_sf: udp %s %s: %s\n", host, port, strerror(errno));
        return -1;
    }
    t->udp = 1;
    t->fd_in = t->fd_out = fd;
    return 0;
}

/* --- the session ------------------------------------------------------------------------------- */

typedef struct {
    double timeout_s;
    double wait_start_s; /* 0: as long as the server holds the session (repeating the held sample) */
    const char *trace_path;
    const char *name;
    long sessions; /* 0: until the server stops answering HELLO */
} options;

typedef struct {
    unsigned long ignored; /* frames counted and ignored: rejected, another session, stale, unexpected */
    unsigned long answered;
} counts;

static int send_typed(transport *t, bb_frame *f)
{
    uint8_t buf[BB_MAX_FRAME_LEN];
    size_t len = bb_encode(f, buf, sizeof buf);
    return len == 0 ? -1 : send_frame(t, buf, len);
}

static void send_stop(transport *t, uint32_t session, uint32_t reason)
{
    bb_frame f;
    memset(&f, 0, sizeof f);
    f.type = BB_STOP;
    f.session = session;
    f.u.stop.reason = reason;
    (void)send_typed(t, &f); /* best effort: the peer may be gone */
}

static int finite_config(const bb_config *c)
{
    const double v[] = {c->period_s,           c->sample_rate_hz,       c->dac_min_v,
                        c->dac_max_v,          c->zero_command_v,       c->ball_gain_m_per_v,
                        c->ball_offset_m,      c->angle_gain_deg_per_v, c->angle_reference_v,
                        c->angle_reference_motor_deg, c->angle_gear_ratio, c->software_pi,
                        c->command_gain_v_per_v, c->command_zero_v,    c->command_low_v,
                        c->command_high_v};
    for (size_t i = 0; i < sizeof v / sizeof v[0]; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* A one-line reason why this controller cannot run on the CONFIG's rig, or NULL. */
static const char *config_problem(const bb_config *c, char *msg, size_t cap)
{
    if (c->mode != BB_MODE_LOCKSTEP && c->mode != BB_MODE_REALTIME)
        snprintf(msg, cap, "CONFIG mode = %u is not 1 (lock-step) or 2 (real time)", c->mode);
    else if (c->ball_block != 0 || c->angle_block != 1)
        snprintf(msg, cap,
                 "CONFIG ball_block = %u, angle_block = %u: appendix A reduces a block to its last ball "
                 "sample (0) and its mean angle (1)",
                 c->ball_block, c->angle_block);
    else if (!finite_config(c))
        snprintf(msg, cap, "CONFIG holds a value that is not finite");
    else if (fabs(c->period_s - PERIOD_S) > PERIOD_TOLERANCE_S)
        snprintf(msg, cap, "CONFIG period_s = %.17g s: the observer is discretised for %g s", c->period_s,
                 PERIOD_S);
    else if (!(c->ball_gain_m_per_v != 0.0 && c->angle_gain_deg_per_v != 0.0 &&
               c->angle_gear_ratio != 0.0 && c->command_gain_v_per_v != 0.0))
        snprintf(msg, cap, "CONFIG has a zero calibration gain or gear ratio");
    else if (!(c->command_low_v < c->command_high_v))
        snprintf(msg, cap, "CONFIG command_low_v = %.17g V is not below command_high_v = %.17g V",
                 c->command_low_v, c->command_high_v);
    else if (!(c->dac_min_v < c->dac_max_v))
        snprintf(msg, cap, "CONFIG dac_min_v = %.17g V is not below dac_max_v = %.17g V", c->dac_min_v,
                 c->dac_max_v);
    else
        return NULL;
    return msg;
}

static void trace_line(FILE *tr, uint32_t seq, const sf_state *s, double command_v)
{
    if (tr == NULL) return;
    fprintf(tr, "%lu %a %a %a %a %a %a %a\n", (unsigned long)seq, s->x1, s->x2, s->x3, s->x4, s->u,
            s->u_temp, command_v);
}

static const char *stop_reason_text(uint32_t reason)
{
    switch (reason) {
    case BB_STOP_DONE: return "done";
    case BB_STOP_CLIENT_QUIT: return "client quit";
    case BB_STOP_BALL_LOST: return "ball lost";
    case BB_STOP_ERROR: return "error";
    case BB_STOP_SHUTDOWN: return "server shutting down";
    default: return "unknown reason";
    }
}

/* One session; *session is its id once CONFIG came. A CONFIG of the previous session (prev, when
 * has_prev: a late answer to a repeated HELLO on the same socket) is not this session's. */
static int run_session(transport *t, const options *o, FILE *tr, int has_prev, uint32_t prev,
                       uint32_t *session_out)
{
    int timeout_ms = (int)(o->timeout_s * 1000.0);
    uint8_t buf[BB_MAX_FRAME_LEN];
    size_t len = 0;
    bb_frame f;
    counts n = {0, 0};
    char msg[200];

    /* HELLO until CONFIG */
    bb_frame hello;
    memset(&hello, 0, sizeof hello);
    hello.type = BB_HELLO;
    hello.u.hello.role = BB_ROLE_CONTROL;
    snprintf(hello.u.hello.client, sizeof hello.u.hello.client, "%s", o->name);
    double give_up = now_s() + o->timeout_s;
    bb_config cfg;
    int configured = 0;
    while (!configured) {
        if (send_typed(t, &hello) != 0 && !t->udp) {
            fprintf(stderr, "bb_sf: cannot write HELLO to stdout: %s\n", strerror(errno));
            return 1;
        }
        double repeat_at = now_s() + HELLO_REPEAT_MS / 1000.0;
        for (;;) {
            double left = (t->udp ? repeat_at : give_up) - now_s();
            int r = receive(t, buf, &len, left > 0 ? (int)(left * 1000.0) : 0);
            if (r == RX_QUIT) {
                fprintf(stderr, "bb_sf: interrupted (signal %d) before CONFIG\n", (int)quit_signal);
                return 128 + quit_signal;
            }
            if (r == RX_EOF) {
                fprintf(stderr, "bb_sf: the server closed the stream before CONFIG\n");
                return SESSION_FATAL;
            }
            if (r == RX_TIMEOUT) break;
            if (r < 0 || bb_decode(buf, len, &f) != BB_OK || f.type != BB_CONFIG ||
                (has_prev && f.session == prev)) {
                n.ignored++;
                continue;
            }
            cfg = f.u.config;
            hello.session = f.session;
            configured = 1;
            break;
        }
        if (!configured && now_s() >= give_up) return SESSION_NO_CONFIG; /* main says why */
    }
    uint32_t session = hello.session;
    *session_out = session;
    if (cfg.role != BB_ROLE_CONTROL) {
        fprintf(stderr, "bb_sf: the server %s control (CONFIG role = %u): another client controls\n",
                cfg.role == BB_ROLE_OBSERVE ? "granted observe only, not" : "refused", cfg.role);
        return SESSION_FATAL; /* asking again would be refused again */
    }
    if (config_problem(&cfg, msg, sizeof msg) != NULL) {
        fprintf(stderr, "bb_sf: %s\n", msg);
        send_stop(t, session, BB_STOP_ERROR);
        return SESSION_FATAL; /* this controller cannot run on that rig: nor on its next session */
    }
    sf_calibration cal = {cfg.ball_gain_m_per_v,    cfg.ball_offset_m,
                          cfg.angle_gain_deg_per_v, cfg.angle_reference_v,
                          cfg.angle_reference_motor_deg, cfg.angle_gear_ratio,
                          cfg.software_pi,          cfg.command_gain_v_per_v,
                          cfg.command_zero_v,       cfg.command_low_v,
                          cfg.command_high_v};

    sf_state sf;
    int started = 0, last_seen = 0, told_held = 0;
    uint32_t last_seq = 0;
    double answered_at = 0.0; /* when the latest new sample was answered */
    unsigned long repeats = 0; /* of that sample since */
    double last_command_v = cfg.zero_command_v;
    bb_frame cmd;
    memset(&cmd, 0, sizeof cmd);
    cmd.type = BB_COMMAND;
    cmd.session = session;
    for (;;) {
        int r = receive(t, buf, &len, timeout_ms);
        if (r == RX_QUIT) {
            send_stop(t, session, BB_STOP_CLIENT_QUIT);
            fprintf(stderr, "bb_sf: interrupted (signal %d) after sample %lu: sent STOP 1 (client quit)\n",
                    (int)quit_signal, (unsigned long)last_seq);
            return 128 + quit_signal;
        }
        if (r == RX_TIMEOUT || r == RX_EOF) {
            if (last_seen) { /* the last sample was answered: a STOP lost on the way ends it as well */
                fprintf(stderr, "bb_sf: session %lu ended after the last sample (seq %lu) without a STOP; "
                        "%lu answered, %lu frames ignored\n", (unsigned long)session,
                        (unsigned long)last_seq, n.answered, n.ignored);
                return 0;
            }
            fprintf(stderr, "bb_sf: %s from the server for %g s (--timeout) after sample %lu: giving up\n",
                    r == RX_EOF ? "end of stream and no STOP" : "no frame", o->timeout_s,
                    (unsigned long)last_seq);
            return 1;
        }
        if (r < 0 || bb_decode(buf, len, &f) != BB_OK || f.session != session) {
            n.ignored++;
            continue;
        }
        if (f.type == BB_STOP) {
            uint32_t why = f.u.stop.reason;
            fprintf(stderr, "bb_sf: session %lu stopped by the server: %s (reason %lu) after sample %lu; "
                    "%lu answered, %lu frames ignored\n", (unsigned long)session, stop_reason_text(why),
                    (unsigned long)why, (unsigned long)last_seq, n.answered, n.ignored);
            return why == BB_STOP_DONE ? 0 : 1;
        }
        if (f.type != BB_SAMPLE) {
            n.ignored++; /* a repeated CONFIG, or a frame a client never receives */
            continue;
        }
        const bb_sample *s = &f.u.sample;
        if (started && f.seq == last_seq) { /* the same sample again: the same answer, no new tick */
            double waited = now_s() - answered_at;
            int held = f.seq == 0 && (s->flags & BB_FLAG_HELD);
            double limit = held ? o->wait_start_s : o->timeout_s;
            repeats++;
            if (limit > 0.0 && waited >= limit) {
                if (held)
                    fprintf(stderr, "bb_sf: the session did not start within %g s (--wait-start): the server "
                            "held the rig, repeating sample 0 %lu times after our acknowledgement; sent "
                            "STOP 1\n", limit, repeats);
                else
                    fprintf(stderr, "bb_sf: no sample after %lu for %g s (--timeout): the server repeated it "
                            "%lu times, our commands do not reach it; sent STOP 1\n", (unsigned long)f.seq,
                            limit, repeats);
                send_stop(t, session, BB_STOP_CLIENT_QUIT);
                return 1;
            }
            if (held && !told_held && waited >= 1.0) { /* not a lost answer: the server holds the run */
                fprintf(stderr, "bb_sf: session %lu: connected, the held sample acknowledged; waiting for the "
                        "server to start the run (the live view starts it when a browser connects)\n",
                        (unsigned long)session);
                told_held = 1;
            }
            cmd.seq = f.seq;
            cmd.u.command.dac_v = last_command_v;
            (void)send_typed(t, &cmd);
            continue;
        }
        if (started && f.seq < last_seq) { /* a stale sample, out of order */
            n.ignored++;
            continue;
        }
        double command_v;
        if (!started) { /* Start / Clear Buffer: the held rig's block sets x1(1), x2(1) */
            if (sf_start(&sf, &cal, s->ball_v, s->angle_v) != 0) {
                fprintf(stderr, "bb_sf: sample %lu: ball_v = %g V, angle_v = %g V: not finite; stopping\n",
                        (unsigned long)f.seq, s->ball_v, s->angle_v);
                send_stop(t, session, BB_STOP_ERROR);
                return 1;
            }
            started = 1;
            command_v = cfg.zero_command_v; /* acknowledged; the rig is held, the volts are not applied */
        } else if (sf_update(&sf, s->ball_v, s->angle_v, &command_v) != 0) {
            fprintf(stderr, "bb_sf: sample %lu: ball_v = %g V, angle_v = %g V give a command that is not "
                    "finite; stopping\n", (unsigned long)f.seq, s->ball_v, s->angle_v);
            send_stop(t, session, BB_STOP_ERROR);
            return 1;
        } else if (!(cfg.dac_min_v <= command_v && command_v <= cfg.dac_max_v)) {
            fprintf(stderr, "bb_sf: sample %lu: command %.17g V is outside the DAC's %g … %g V; stopping\n",
                    (unsigned long)f.seq, command_v, cfg.dac_min_v, cfg.dac_max_v);
            send_stop(t, session, BB_STOP_ERROR);
            return 1;
        }
        last_seq = f.seq;
        last_command_v = command_v;
        answered_at = now_s();
        repeats = 0;
        trace_line(tr, f.seq, &sf, command_v);
        if (tr != NULL) fflush(tr); /* before the answer: a reader of the trace has the line with it */
        /* the last sample is answered too: a server that does not wait ignores it, one that logs
           the tick's command has it */
        cmd.seq = f.seq;
        cmd.u.command.dac_v = command_v;
        if (send_typed(t, &cmd) != 0 && !t->udp) {
            fprintf(stderr, "bb_sf: cannot write COMMAND %lu to stdout: %s\n", (unsigned long)f.seq,
                    strerror(errno));
            return SESSION_FATAL;
        }
        n.answered++;
        if (s->flags & BB_FLAG_LAST) last_seen = 1;
    }
}

/* --- selftest and crc: the codec seen from outside ----------------------------------------------- */

static void print_text(const char *key, const char *s)
{
    printf(" %s=", key);
    for (; *s; s++) {
        unsigned char ch = (unsigned char)*s;
        if (ch > 32 && ch < 127 && ch != '\\') putchar(ch);
        else printf("\\x%02x", ch);
    }
}

static int selftest(void)
{
    transport t;
    memset(&t, 0, sizeof t);
    t.fd_in = 0;
    uint8_t buf[BB_MAX_FRAME_LEN], again[BB_MAX_FRAME_LEN];
    size_t len = 0;
    bb_frame f;
    for (;;) {
        int r = stream_next(&t, buf, &len, 10000);
        if (r == RX_EOF || r == RX_TIMEOUT) break;
        int status = r < 0 ? r : bb_decode(buf, len, &f);
        if (status != BB_OK) {
            printf("REJECTED %s\n", bb_status_text(status));
            continue;
        }
        printf("type=%u seq=%lu session=%lu", f.type, (unsigned long)f.seq, (unsigned long)f.session);
        switch (f.type) {
        case BB_HELLO:
            printf(" role=%u", f.u.hello.role);
            print_text("client", f.u.hello.client);
            break;
        case BB_CONFIG: {
            const bb_config *c = &f.u.config;
            printf(" role=%u mode=%u ball_block=%u angle_block=%u period_s=%a sample_rate_hz=%a "
                   "watchdog_periods=%lu dac_min_v=%a dac_max_v=%a zero_command_v=%a "
                   "ball_gain_m_per_v=%a ball_offset_m=%a angle_gain_deg_per_v=%a angle_reference_v=%a "
                   "angle_reference_motor_deg=%a angle_gear_ratio=%a software_pi=%a "
                   "command_gain_v_per_v=%a command_zero_v=%a command_low_v=%a command_high_v=%a",
                   c->role, c->mode, c->ball_block, c->angle_block, c->period_s, c->sample_rate_hz,
                   (unsigned long)c->watchdog_periods, c->dac_min_v, c->dac_max_v, c->zero_command_v,
                   c->ball_gain_m_per_v, c->ball_offset_m, c->angle_gain_deg_per_v, c->angle_reference_v,
                   c->angle_reference_motor_deg, c->angle_gear_ratio, c->software_pi,
                   c->command_gain_v_per_v, c->command_zero_v, c->command_low_v, c->command_high_v);
            print_text("rig", c->rig);
            break;
        }
        case BB_SAMPLE:
            printf(" time_s=%a ball_v=%a angle_v=%a flags=%lu applied_seq=%lu", f.u.sample.time_s,
                   f.u.sample.ball_v, f.u.sample.angle_v, (unsigned long)f.u.sample.flags,
                   (unsigned long)f.u.sample.applied_seq);
            break;
        case BB_COMMAND: printf(" dac_v=%a", f.u.command.dac_v); break;
        case BB_STOP: printf(" reason=%lu", (unsigned long)f.u.stop.reason); break;
        default: break;
        }
        size_t n = bb_encode(&f, again, sizeof again);
        printf(" encoded=");
        for (size_t i = 0; i < n; i++) printf("%02x", again[i]);
        printf("\n");
    }
    if (t.skipped_bytes) printf("SKIPPED %lu\n", t.skipped_bytes);
    return 0;
}

static int crc_of_stdin(void)
{
    static uint8_t data[1 << 16];
    size_t n = fread(data, 1, sizeof data, stdin);
    printf("%08lx\n", (unsigned long)bb_crc32(data, n));
    return 0;
}

/* --- main -------------------------------------------------------------------------------------- */

static int usage(const char *problem)
{
    if (problem != NULL) fprintf(stderr, "bb_sf: %s\n", problem);
    fprintf(stderr, "usage: bb_sf udp HOST PORT [--timeout S] [--wait-start S] [--trace PATH] [--name NAME] "
                    "[--sessions N]\n"
                    "       bb_sf pipe [--timeout S] [--wait-start S] [--trace PATH] [--name NAME] "
                    "[--sessions N]\n"
                    "       bb_sf selftest | bb_sf crc\n");
    return 2;
}

int main(int argc, char **argv)
{
    if (argc < 2) return usage(NULL);
    const char *mode = argv[1];
    if (strcmp(mode, "selftest") == 0 && argc == 2) return selftest();
    if (strcmp(mode, "crc") == 0 && argc == 2) return crc_of_stdin();
    if (strcmp(mode, "-h") == 0 || strcmp(mode, "--help") == 0) {
        usage(NULL);
        return 0;
    }
    int first_option;
    if (strcmp(mode, "udp") == 0) {
        if (argc < 4) return usage("udp needs HOST and PORT");
        first_option = 4;
    } else if (strcmp(mode, "pipe") == 0) {
        first_option = 2;
    } else {
        char msg[120];
        snprintf(msg, sizeof msg, "unknown mode '%.60s'", mode);
        return usage(msg);
    }
    options o = {10.0, 0.0, NULL, "bb_sf appendix-sf (C99)", 1};
    for (int i = first_option; i < argc; i++) {
        if (i + 1 >= argc) return usage("an option needs a value");
        if (strcmp(argv[i], "--timeout") == 0) {
            char *end = NULL;
            o.timeout_s = strtod(argv[i + 1], &end);
            if (end == argv[i + 1] || *end != '\0' || !(o.timeout_s > 0.0 && o.timeout_s <= 3600.0)) {
                fprintf(stderr, "bb_sf: --timeout %s: a number of seconds in (0, 3600]\n", argv[i + 1]);
                return 2;
            }
        } else if (strcmp(argv[i], "--wait-start") == 0) {
            char *end = NULL;
            o.wait_start_s = strtod(argv[i + 1], &end);
            if (end == argv[i + 1] || *end != '\0' || !(o.wait_start_s >= 0.0 && o.wait_start_s <= 86400.0)) {
                fprintf(stderr, "bb_sf: --wait-start %s: a number of seconds in [0, 86400] (0: no limit)\n",
                        argv[i + 1]);
                return 2;
            }
        } else if (strcmp(argv[i], "--trace") == 0) {
            o.trace_path = argv[i + 1];
        } else if (strcmp(argv[i], "--name") == 0) {
            o.name = argv[i + 1];
        } else if (strcmp(argv[i], "--sessions") == 0) {
            char *end = NULL;
            errno = 0;
            o.sessions = strtol(argv[i + 1], &end, 10);
            if (end == argv[i + 1] || *end != '\0' || errno != 0 || o.sessions < 0) {
                fprintf(stderr, "bb_sf: --sessions %s: a whole number >= 0 (0: until none comes)\n",
                        argv[i + 1]);
                return 2;
            }
        } else {
            char msg[120];
            snprintf(msg, sizeof msg, "unknown option '%.60s'", argv[i]);
            return usage(msg);
        }
        i++;
    }
    struct sigaction quit;
    memset(&quit, 0, sizeof quit);
    quit.sa_handler = on_quit_signal; /* no SA_RESTART: a blocking wait returns to see the flag */
    sigemptyset(&quit.sa_mask);
    sigaction(SIGINT, &quit, NULL);
    sigaction(SIGTERM, &quit, NULL);
    signal(SIGPIPE, SIG_IGN); /* a closed pipe is a failed write (reported), not a silent death */
    transport t;
    memset(&t, 0, sizeof t);
    if (strcmp(mode, "udp") == 0) {
        if (open_udp(&t, argv[2], argv[3]) != 0) return 1;
    } else {
        t.fd_in = 0;
        t.fd_out = 1;
    }
    FILE *tr = NULL;
    if (o.trace_path != NULL) {
        tr = strcmp(o.trace_path, "-") == 0 ? stderr : fopen(o.trace_path, "w");
        if (tr == NULL) {
            fprintf(stderr, "bb_sf: --trace %s: %s\n", o.trace_path, strerror(errno));
            return 2;
        }
    }
    long done = 0;
    int failed = 0, has_prev = 0;
    uint32_t prev = 0;
    while (o.sessions == 0 || done < o.sessions) {
        uint32_t session = 0;
        int rc = run_session(&t, &o, tr, has_prev, prev, &session);
        if (rc >= 128) return rc;
        if (rc == SESSION_NO_CONFIG) {
            if (o.sessions == 0 && done > 0) break; /* the served job is over */
            fprintf(stderr, "bb_sf: no CONFIG from the server within %g s (--timeout)", o.timeout_s);
            if (o.sessions != 1) fprintf(stderr, " (after %ld sessions)", done);
            fprintf(stderr, "\n");
            return 1;
        }
        done++;
        has_prev = 1;
        prev = session;
        if (rc != 0) failed = 1;
        if (rc == SESSION_FATAL) break;
    }
    if (o.sessions != 1)
        fprintf(stderr, "bb_sf: %ld sessions, %s\n", done,
                failed ? "not all as the server said" : "each as the server said");
    return failed ? 1 : 0;
}
