/*
 * Runs the real firmware (ELF for the ATmega328P) in simavr and measures its
 * waveforms cycle-exactly: protocol over the simulated UART, trigger edge on
 * INT0 (PD2), output edges on PD4..PD7.
 *
 *   cc -std=gnu99 -O1 -o sim_test sim_test.c -lsimavr
 *   ./sim_test ../build/rollcam-led.elf
 *
 * Needs libsimavr (Debian: apt-get install -y libsimavr-dev). Prints the
 * measured edge timing per channel and ends with "N passed, N failed".
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

#define F_CPU 16000000.0
#define MAX_EDGES 4096

static avr_t *avr;
static char rx[4096];
static size_t rx_len;

struct edge {
    uint64_t cycle;
    int rising;
};
static struct edge edges[4][MAX_EDGES];
static int nedges[4];

static int passed, failed;

static void check(int ok, const char *what)
{
    if (ok)
        passed++;
    else
        failed++;
    printf("%s %s\n", ok ? "ok  " : "FAIL", what);
}

static double us(uint64_t cycles) { return (double)cycles * 1e6 / F_CPU; }

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    (void)param;
    if (rx_len < sizeof rx - 1)
        rx[rx_len++] = (char)value;
    rx[rx_len] = 0;
}

static void pin_changed(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq;
    int ch = (int)(intptr_t)param;
    if (nedges[ch] < MAX_EDGES) {
        edges[ch][nedges[ch]].cycle = avr->cycle;
        edges[ch][nedges[ch]].rising = value != 0;
        nedges[ch]++;
    }
}

static void run_until(uint64_t cycle)
{
    while (avr->cycle < cycle) {
        int st = avr_run(avr);
        if (st == cpu_Done || st == cpu_Crashed) {
            printf("FAIL cpu stopped (state %d)\n", st);
            exit(1);
        }
    }
}

static void run_us(double t) { run_until(avr->cycle + (uint64_t)(t * F_CPU / 1e6)); }

static uint8_t crc8(const char *p, size_t n)
{
    uint8_t c = 0;
    while (n--) {
        c ^= (uint8_t)*p++;
        for (int i = 0; i < 8; i++)
            c = (c & 0x80) ? (uint8_t)((c << 1) ^ 7) : (uint8_t)(c << 1);
    }
    return c;
}

/* Sends "$<inner>*HH\n" byte by byte at ~115200 baud, returns the reply line (static). */
static const char *request(const char *inner)
{
    char line[160];
    snprintf(line, sizeof line, "$%s*%02X\n", inner, crc8(inner, strlen(inner)));
    rx_len = 0;
    rx[0] = 0;
    avr_irq_t *in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    for (const char *p = line; *p; p++) {
        avr_raise_irq(in, (uint8_t)*p);
        run_us(90);
    }
    for (int i = 0; i < 200 && !strchr(rx, '\n'); i++)
        run_us(100);
    char *nl = strchr(rx, '\n');
    if (nl)
        *nl = 0;
    return rx;
}

static int starts(const char *s, const char *prefix) { return strncmp(s, prefix, strlen(prefix)) == 0; }

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: %s rollcam-led.elf\n", argv[0]);
        return 2;
    }
    elf_firmware_t fw;
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(argv[1], &fw) != 0) {
        fprintf(stderr, "cannot read %s\n", argv[1]);
        return 2;
    }
    avr = avr_make_mcu_by_name("atmega328p");
    if (!avr) {
        fprintf(stderr, "simavr has no atmega328p\n");
        return 2;
    }
    avr_init(avr);
    avr_load_firmware(avr, &fw);
    avr->frequency = (uint32_t)F_CPU;
    avr->log = 0;

    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
    for (int c = 0; c < 4; c++)
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 4 + c), pin_changed,
                                (void *)(intptr_t)c);
    avr_irq_t *trig = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
    avr_raise_irq(trig, 0);

    run_us(2000);
    const char *r = request("1 ID");
    printf("     ID -> %s\n", r);
    check(starts(r, "$1 ACK name=rollcam-led proto=1 ") && strstr(r, " hw=uno ") && strstr(r, " tick_ns=500"),
          "ID answered by the firmware");

    static const unsigned period[4] = {2640, 1980, 1320, 660};
    static const unsigned phase[4] = {0, 100, 250, 1000};
    static const unsigned count[4] = {0, 0, 0, 5};
    char cmd[96];
    for (int c = 0; c < 4; c++) {
        snprintf(cmd, sizeof cmd, "%d CFG %d %u %u %u %u", 10 + c, c, period[c], period[c] / 2, phase[c], count[c]);
        r = request(cmd);
        char want[32];
        snprintf(want, sizeof want, "$%d ACK*", 10 + c);
        check(starts(r, want), "CFG acknowledged");
    }
    r = request("20 CFG 0 50 25 0 0");
    check(starts(r, "$20 NAK 6 RANGE*"), "CFG period 50 refused with NAK 6 RANGE");
    r = request("21 TRIG");
    check(starts(r, "$21 NAK 7 STATE*"), "TRIG while idle refused with NAK 7 STATE");
    r = request("24 ARM FALL");
    check(starts(r, "$24 ACK*"), "ARM FALL acknowledged");
    for (int c = 0; c < 4; c++)
        nedges[c] = 0;
    run_us(500);
    check(nedges[0] + nedges[1] + nedges[2] + nedges[3] == 0, "outputs idle while armed");
    avr_raise_irq(trig, 1); /* rising: ignored in FALL mode */
    run_us(1000);
    check(nedges[0] + nedges[1] + nedges[2] + nedges[3] == 0, "rising edge ignored when armed for FALL");
    uint64_t t0 = avr->cycle;
    avr_raise_irq(trig, 0); /* falling: t = 0 */

    /* 20 ms of waveform, with UART traffic in the middle (interrupt load). */
    run_us(5000);
    r = request("25 STAT");
    printf("     STAT -> %s\n", r);
    check(starts(r, "$25 ACK state=RUNNING arm=FALL en=1111 t_us="), "STAT reports RUNNING");
    long t_us = strstr(r, "t_us=") ? atol(strstr(r, "t_us=") + 5) : -1;
    check(t_us > 5000 && t_us < 20000, "STAT t_us counts from the trigger");
    run_until(t0 + (uint64_t)(20000 * F_CPU / 1e6));
    uint64_t t_end = avr->cycle;
    r = request("26 STOP");
    check(starts(r, "$26 ACK*"), "STOP acknowledged");

    /* Ideal edge times of every channel, to tell isolated edges from edges that
     * follow another channel's edge closely (those wait for the previous
     * compare ISR to finish). */
    static double ideal[4][MAX_EDGES];
    static int nideal[4];
    for (int c = 0; c < 4; c++) {
        nideal[c] = 0;
        for (int i = 0; i < MAX_EDGES; i++) {
            unsigned k = (unsigned)(i / 2);
            if (count[c] && k >= count[c])
                break;
            double t = phase[c] + (double)k * period[c] + ((i % 2) ? period[c] / 2.0 : 0);
            if (t >= 20000)
                break;
            ideal[c][nideal[c]++] = t;
        }
    }
    double iso_lo = 1e9, iso_hi = -1e9, crowd_lo = 1e9, crowd_hi = -1e9;
    int n_iso = 0, n_crowd = 0;
    for (int c = 0; c < 4; c++) {
        int n = 0, ok = 1;
        for (int i = 0; i < nedges[c] && edges[c][i].cycle <= t_end; i++) {
            n++;
            if (i >= nideal[c] || edges[c][i].rising != !(i % 2)) {
                ok = 0;
                continue;
            }
            double err = us(edges[c][i].cycle - t0) - ideal[c][i];
            int crowded = 0;
            for (int o = 0; o < 4; o++)
                for (int j = 0; o != c && j < nideal[o]; j++)
                    if (ideal[o][j] <= ideal[c][i] && ideal[c][i] - ideal[o][j] < 60.0 &&
                        ideal[c][i] - ideal[o][j] >= 2.0)
                        crowded = 1;
            if (i == 0 && phase[c] == 0)
                crowded = 1; /* output by the INT0 ISR itself, see below */
            if (getenv("SIM_VERBOSE"))
                printf("     ch%d edge %2d ideal %8.1f us error %+6.2f us%s\n", c, i, ideal[c][i], err,
                       crowded ? " (crowded)" : "");
            if (crowded) {
                n_crowd++;
                crowd_lo = err < crowd_lo ? err : crowd_lo;
                crowd_hi = err > crowd_hi ? err : crowd_hi;
            } else {
                n_iso++;
                iso_lo = err < iso_lo ? err : iso_lo;
                iso_hi = err > iso_hi ? err : iso_hi;
            }
        }
        /* The last continuous edge may straddle the 20 ms boundary. */
        int expected = nideal[c];
        char what[96];
        snprintf(what, sizeof what, "ch%d: %d edges (ideal %d), polarity alternates from rising", c, n, expected);
        check(ok && (n == expected || (!count[c] && n == expected - 1)), what);
    }
    printf("     isolated edges (%d): error vs ideal %+.2f .. %+.2f us (t = 0 at the INT0 edge)\n", n_iso, iso_lo,
           iso_hi);
    printf("     crowded edges  (%d): error vs ideal %+.2f .. %+.2f us\n", n_crowd, crowd_lo, crowd_hi);
    check(n_iso > 50 && iso_lo >= -1.0 && iso_hi <= 1.0, "isolated edges within 1 us of their ideal time");
    check(n_crowd > 0 && crowd_lo >= -2.5 && crowd_hi <= 50.0,
          "edges crowded by another channel's edge (< 60 us before) or at t = 0 within -2.5..+50 us");
    check(edges[0][0].rising && us(edges[0][0].cycle - t0) < 4.0, "phase-0 output rises within 4 us of the INT0 edge");

    int after = 0;
    for (int c = 0; c < 4; c++)
        after += nedges[c] && edges[c][nedges[c] - 1].rising;
    check(after == 0, "all outputs low after STOP");

    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
