/*
 * rollcam LED pulse controller: portable protocol engine.
 *
 * Mirrors hw/src/led/protocol.rs and the Device model in
 * hw/src/led/emulator.rs; both are checked against vectors.txt.
 * No dynamic memory, no stdio, no floating point (fits an ATmega328P).
 */
#include <string.h>
#include "proto.h"

enum { ST_IDLE, ST_ARMED, ST_TRIGGERED };

static struct led_chan cfg[CHANNELS];
static uint8_t enabled_mask;
static uint8_t state;
static uint8_t arm_mode;

/* Line assembly. Content excludes the final '\n'. */
static char line[MAX_LINE];
static uint8_t line_len;
static uint8_t in_line;
static uint8_t overflow;

/* Last executed request, for idempotent retransmissions. */
static uint16_t last_seq;
static uint8_t last_crc;
static uint8_t have_last;
static char last_reply[MAX_LINE];
static uint8_t last_reply_len;

/* Reply under construction. */
static char out[MAX_LINE];
static uint8_t out_len;

uint8_t proto_crc8(const uint8_t *p, uint8_t n)
{
    uint8_t crc = 0;
    while (n--) {
        crc ^= *p++;
        for (uint8_t i = 0; i < 8; i++)
            crc = (crc & 0x80) ? (uint8_t)((crc << 1) ^ 0x07) : (uint8_t)(crc << 1);
    }
    return crc;
}

static void out_str(const char *s)
{
    while (*s && out_len < MAX_LINE - 4)
        out[out_len++] = *s++;
}

static void out_u32(uint32_t v)
{
    char tmp[11];
    uint8_t n = 0;
    do {
        tmp[n++] = (char)('0' + v % 10);
        v /= 10;
    } while (v);
    while (n && out_len < MAX_LINE - 4)
        out[out_len++] = tmp[--n];
}

static void out_kv(const char *key, uint32_t v)
{
    out_str(" ");
    out_str(key);
    out_str("=");
    out_u32(v);
}

static const char hexd[] = "0123456789ABCDEF";

/* Starts a reply "$<seq> " (the '$' is not part of the CRC). */
static void reply_begin(uint16_t seq)
{
    out_len = 0;
    out[out_len++] = '$';
    out_u32(seq);
    out_str(" ");
}

/* Appends "*HH\n" and sends. */
static void reply_end(void)
{
    uint8_t crc = proto_crc8((const uint8_t *)out + 1, (uint8_t)(out_len - 1));
    out[out_len++] = '*';
    out[out_len++] = hexd[crc >> 4];
    out[out_len++] = hexd[crc & 15];
    out[out_len++] = '\n';
    hal_write(out, out_len);
}

static void send_nak(uint16_t seq, uint8_t code)
{
    static const char *const names[] = {"", "CRC", "FRAME", "OVERSIZE", "UNKNOWN", "ARGS", "RANGE", "STATE"};
    reply_begin(seq);
    out_str("NAK ");
    out_u32(code);
    out_str(" ");
    out_str(names[code]);
    reply_end();
}

static uint8_t is_digit(char c) { return c >= '0' && c <= '9'; }

static int8_t hexval(char c)
{
    if (c >= '0' && c <= '9') return (int8_t)(c - '0');
    if (c >= 'A' && c <= 'F') return (int8_t)(c - 'A' + 10);
    if (c >= 'a' && c <= 'f') return (int8_t)(c - 'a' + 10);
    return -1;
}

/* Strict decimal: 1..10 digits and <= 0xFFFFFFFF. Returns 0 ok, E_ARGS, E_RANGE. */
static uint8_t parse_u32(const char *s, uint8_t n, uint32_t *v)
{
    if (n == 0)
        return E_ARGS;
    for (uint8_t i = 0; i < n; i++)
        if (!is_digit(s[i]))
            return E_ARGS;
    if (n > 10)
        return E_RANGE;
    uint32_t acc = 0;
    for (uint8_t i = 0; i < n; i++) {
        uint8_t d = (uint8_t)(s[i] - '0');
        if (acc > 429496729UL || (acc == 429496729UL && d > 5))
            return E_RANGE;
        acc = acc * 10 + d;
    }
    *v = acc;
    return 0;
}

#define MAX_TOK 7
static const char *tok[MAX_TOK];
static uint8_t tok_len[MAX_TOK];
static uint8_t ntok; /* true count, may exceed MAX_TOK */

static void tokenize(const char *s, uint8_t n)
{
    ntok = 0;
    uint8_t i = 0;
    while (i < n) {
        while (i < n && s[i] == ' ')
            i++;
        if (i >= n)
            break;
        uint8_t start = i;
        while (i < n && s[i] != ' ')
            i++;
        if (ntok < MAX_TOK) {
            tok[ntok] = s + start;
            tok_len[ntok] = (uint8_t)(i - start);
        }
        ntok++;
    }
}

static uint8_t word_is(uint8_t t, const char *w)
{
    uint8_t n = (uint8_t)strlen(w);
    return tok_len[t] == n && memcmp(tok[t], w, n) == 0;
}

static uint8_t arg_u32(uint8_t i, uint32_t *v) { return parse_u32(tok[i + 1], tok_len[i + 1], v); }

static uint8_t arg_chan(uint8_t i, uint8_t *ch)
{
    uint32_t v;
    uint8_t e = arg_u32(i, &v);
    if (e)
        return e;
    if (v >= CHANNELS)
        return E_RANGE;
    *ch = (uint8_t)v;
    return 0;
}

static uint8_t valid_cfg(const struct led_chan *c)
{
    if (c->period_us < MIN_PERIOD_US || c->period_us > MAX_PERIOD_US)
        return 0;
    if (c->width_us < MIN_WIDTH_US)
        return 0;
    if (c->period_us - (c->width_us < c->period_us ? c->width_us : c->period_us) < MIN_WIDTH_US)
        return 0;
    if (c->phase_us > MAX_PHASE_US)
        return 0;
    if (c->count > MAX_COUNT)
        return 0;
    return 1;
}

static void sync_state(void)
{
    if (state == ST_ARMED && hal_fired())
        state = ST_TRIGGERED;
}

static uint8_t running(void) { return state == ST_TRIGGERED && hal_running(); }

static uint8_t may_configure(void) { return state == ST_IDLE || (state == ST_TRIGGERED && !hal_running()); }

/* A finished run is left when the device is reconfigured or re-armed. */
static void settle_done(void)
{
    if (state == ST_TRIGGERED) {
        hal_stop();
        state = ST_IDLE;
    }
}

static const char *mode_token(uint8_t m)
{
    switch (m) {
    case ARM_SW: return "SW";
    case ARM_RISE: return "RISE";
    case ARM_FALL: return "FALL";
    default: return "-";
    }
}

/* Executes the command in tok[]. On success builds the ACK in out[] (not yet
 * terminated) and returns 0; otherwise returns the NAK code and acts on nothing. */
static uint8_t execute(uint16_t seq)
{
    uint8_t nargs = (uint8_t)(ntok - 1);
    uint8_t e;
#define NAK(code) return (code)
#define WANT(n)       \
    if (nargs != (n)) \
    NAK(E_ARGS)

    if (word_is(0, "ID")) {
        WANT(0);
        reply_begin(seq);
        out_str("ACK name=" DEVICE_NAME);
        out_kv("proto", PROTOCOL_VERSION);
        out_str(" fw=" FW_VERSION " hw=" HW_NAME);
        out_kv("ch", CHANNELS);
        out_kv("tick_ns", TICK_NS);
    } else if (word_is(0, "CFG")) {
        uint32_t v[5];
        WANT(5);
        for (uint8_t i = 0; i < 5; i++)
            if ((e = arg_u32(i, &v[i])) != 0)
                NAK(e);
        if (v[0] >= CHANNELS)
            NAK(E_RANGE);
        struct led_chan c = {v[1], v[2], v[3], v[4]};
        if (!valid_cfg(&c))
            NAK(E_RANGE);
        if (!may_configure())
            NAK(E_STATE);
        settle_done();
        cfg[v[0]] = c;
        enabled_mask |= (uint8_t)(1u << v[0]);
        reply_begin(seq);
        out_str("ACK");
    } else if (word_is(0, "OFF")) {
        uint8_t ch;
        WANT(1);
        if ((e = arg_chan(0, &ch)) != 0)
            NAK(e);
        if (!may_configure())
            NAK(E_STATE);
        settle_done();
        enabled_mask &= (uint8_t)~(1u << ch);
        reply_begin(seq);
        out_str("ACK");
    } else if (word_is(0, "GET")) {
        uint8_t ch;
        WANT(1);
        if ((e = arg_chan(0, &ch)) != 0)
            NAK(e);
        reply_begin(seq);
        out_str("ACK");
        out_kv("ch", ch);
        out_kv("en", (enabled_mask >> ch) & 1u);
        out_kv("period_us", cfg[ch].period_us);
        out_kv("width_us", cfg[ch].width_us);
        out_kv("phase_us", cfg[ch].phase_us);
        out_kv("count", cfg[ch].count);
    } else if (word_is(0, "ARM")) {
        uint8_t m;
        WANT(1);
        if (word_is(1, "SW"))
            m = ARM_SW;
        else if (word_is(1, "RISE"))
            m = ARM_RISE;
        else if (word_is(1, "FALL"))
            m = ARM_FALL;
        else
            NAK(E_ARGS);
        if (running() || enabled_mask == 0)
            NAK(E_STATE);
        settle_done();
        hal_arm(m, cfg, enabled_mask);
        arm_mode = m;
        state = ST_ARMED;
        reply_begin(seq);
        out_str("ACK");
    } else if (word_is(0, "TRIG")) {
        WANT(0);
        if (state != ST_ARMED)
            NAK(E_STATE);
        hal_fire();
        state = ST_TRIGGERED;
        reply_begin(seq);
        out_str("ACK");
    } else if (word_is(0, "STOP")) {
        WANT(0);
        hal_stop();
        state = ST_IDLE;
        reply_begin(seq);
        out_str("ACK");
    } else if (word_is(0, "STAT")) {
        WANT(0);
        reply_begin(seq);
        out_str("ACK state=");
        out_str(state == ST_IDLE ? "IDLE" : state == ST_ARMED ? "ARMED" : running() ? "RUNNING" : "DONE");
        out_str(" arm=");
        out_str(state == ST_IDLE ? "-" : mode_token(arm_mode));
        out_str(" en=");
        for (uint8_t c = 0; c < CHANNELS; c++)
            out_str((enabled_mask >> c) & 1u ? "1" : "0");
        out_kv("t_us", state == ST_TRIGGERED ? hal_elapsed_us() : 0);
    } else {
        NAK(E_UNKNOWN);
    }
    return 0;
#undef NAK
#undef WANT
}

static void handle_line(void)
{
    uint8_t n = line_len;
    /* Strip trailing '\r'. */
    while (n > 1 && line[n - 1] == '\r')
        n--;
    /* line[0] == '$' (guaranteed by the assembler). Every other byte printable. */
    for (uint8_t i = 1; i < n; i++)
        if ((uint8_t)line[i] < 0x20 || (uint8_t)line[i] > 0x7e) {
            send_nak(0, E_FRAME);
            return;
        }
    /* Last '*'. */
    int16_t star = -1;
    for (uint8_t i = 1; i < n; i++)
        if (line[i] == '*')
            star = i;
    if (star < 0 || n - star - 1 != 2) {
        send_nak(0, E_FRAME);
        return;
    }
    int8_t h = hexval(line[star + 1]), l = hexval(line[star + 2]);
    if (h < 0 || l < 0) {
        send_nak(0, E_FRAME);
        return;
    }
    uint8_t carried = (uint8_t)((h << 4) | l);
    const char *inner = line + 1;
    uint8_t inner_len = (uint8_t)(star - 1);
    if (proto_crc8((const uint8_t *)inner, inner_len) != carried) {
        send_nak(0, E_CRC);
        return;
    }
    /* "<seq> <body>": sequence number up to the first space. */
    uint8_t sp = 0;
    while (sp < inner_len && inner[sp] != ' ')
        sp++;
    uint32_t seq32;
    if (parse_u32(inner, sp, &seq32) != 0 || seq32 > MAX_SEQ || seq32 == 0 || sp >= inner_len) {
        send_nak(0, E_FRAME);
        return;
    }
    uint16_t seq = (uint16_t)seq32;
    const char *body = inner + sp + 1;
    uint8_t body_len = (uint8_t)(inner_len - sp - 1);
    while (body_len && *body == ' ') {
        body++;
        body_len--;
    }
    if (body_len == 0) {
        send_nak(0, E_FRAME);
        return;
    }
    if (have_last && seq == last_seq && carried == last_crc) {
        hal_write(last_reply, last_reply_len); /* retransmission: answer again, do not act */
        return;
    }
    sync_state();
    tokenize(body, body_len);
    uint8_t code = execute(seq);
    if (code)
        send_nak(seq, code);
    else
        reply_end();
    memcpy(last_reply, out, out_len);
    last_reply_len = out_len;
    last_seq = seq;
    last_crc = carried;
    have_last = 1;
}

void proto_init(void)
{
    for (uint8_t c = 0; c < CHANNELS; c++) {
        cfg[c].period_us = 1000;
        cfg[c].width_us = 500;
        cfg[c].phase_us = 0;
        cfg[c].count = 0;
    }
    enabled_mask = 0;
    state = ST_IDLE;
    arm_mode = ARM_NONE;
    line_len = 0;
    in_line = 0;
    overflow = 0;
    have_last = 0;
}

void proto_feed(uint8_t b)
{
    if (b == '$') {
        line[0] = '$';
        line_len = 1;
        in_line = 1;
        overflow = 0;
    } else if (b == '\n') {
        if (overflow)
            send_nak(0, E_OVERSIZE);
        else if (in_line)
            handle_line();
        in_line = 0;
        overflow = 0;
        line_len = 0;
    } else if (in_line && !overflow) {
        if (line_len + 1 >= MAX_LINE) {
            overflow = 1;
            line_len = 0;
        } else {
            line[line_len++] = (char)b;
        }
    }
}
