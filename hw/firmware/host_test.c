/*
 * Runs the firmware's protocol engine (proto.c) on a PC against vectors.txt.
 *
 *   cc -std=c99 -DHW_NAME='"test"' -DTICK_NS=500 -o host_test host_test.c proto.c
 *   ./host_test vectors.txt
 *
 * The HAL below is a stand-in with a clock that stands still at t = 0 and a
 * waveform that runs until STOP, matching the assumptions in vectors.txt.
 * Prints one line per failing vector and ends with "N passed, N failed".
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "proto.h"

static char captured[4096];
static size_t captured_len;
static int fired, armed;

void hal_arm(uint8_t mode, const struct led_chan *cfg, uint8_t mask)
{
    (void)mode;
    (void)cfg;
    (void)mask;
    armed = 1;
    fired = 0;
}
void hal_fire(void) { fired = 1; }
uint8_t hal_fired(void) { return (uint8_t)fired; }
uint8_t hal_running(void) { return (uint8_t)fired; }
uint32_t hal_elapsed_us(void) { return 0; }
void hal_stop(void)
{
    fired = 0;
    armed = 0;
}
void hal_write(const char *s, uint8_t n)
{
    if (captured_len + n < sizeof captured) {
        memcpy(captured + captured_len, s, n);
        captured_len += n;
    }
}

static int hexv(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* Unescapes \n \r \t \\ \xHH in place; returns the length or -1. */
static long unescape(char *s)
{
    char *r = s, *w = s;
    while (*r) {
        if (*r != '\\') {
            *w++ = *r++;
            continue;
        }
        r++;
        switch (*r) {
        case 'n': *w++ = '\n'; r++; break;
        case 'r': *w++ = '\r'; r++; break;
        case 't': *w++ = '\t'; r++; break;
        case '\\': *w++ = '\\'; r++; break;
        case 'x': {
            int h = hexv(r[1]), l = hexv(r[2]);
            if (h < 0 || l < 0) return -1;
            *w++ = (char)(h * 16 + l);
            r += 3;
            break;
        }
        default: return -1;
        }
    }
    return (long)(w - s);
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s vectors.txt\n", argv[0]);
        return 2;
    }
    FILE *f = fopen(argv[1], "rb");
    if (!f) {
        perror(argv[1]);
        return 2;
    }
    if (proto_crc8((const uint8_t *)"123456789", 9) != 0xF4) {
        printf("FAIL crc8 check value\n0 passed, 1 failed\n");
        return 1;
    }
    proto_init();
    static char buf[8192];
    int passed = 0, failed = 0, lineno = 0;
    while (fgets(buf, sizeof buf, f)) {
        lineno++;
        size_t n = strlen(buf);
        while (n && (buf[n - 1] == '\n' || buf[n - 1] == '\r'))
            buf[--n] = 0;
        if (n == 0 || buf[0] == '#')
            continue;
        char *sep = strstr(buf, " => ");
        if (!sep) {
            printf("line %d: no ' => '\n", lineno);
            failed++;
            continue;
        }
        *sep = 0;
        char *send = buf, *expect = sep + 4;
        long sn = unescape(send);
        if (sn < 0) {
            printf("line %d: bad escape\n", lineno);
            failed++;
            continue;
        }
        captured_len = 0;
        for (long i = 0; i < sn; i++)
            proto_feed((uint8_t)send[i]);
        char want[512];
        if (strcmp(expect, "-") == 0)
            want[0] = 0;
        else
            snprintf(want, sizeof want, "%s\n", expect);
        if (captured_len == strlen(want) && memcmp(captured, want, captured_len) == 0) {
            passed++;
        } else {
            captured[captured_len] = 0;
            printf("line %d: expected [%s] got [%s]\n", lineno, expect, captured);
            failed++;
        }
    }
    fclose(f);
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
