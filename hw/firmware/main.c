/*
 * rollcam LED pulse controller firmware for ATmega328P @ 16 MHz
 * (Arduino Uno / Nano).
 *
 * Pins (see README.md):
 *   D0/D1 (PD0/PD1)  UART to the host, 115200 8N1
 *   D2    (PD2)      trigger input, INT0 (edge chosen by ARM RISE / ARM FALL)
 *   D4..D7 (PD4..7)  LED channel 0..3 outputs (active high)
 *   D13   (PB5)      on-board LED: lit from ARM until STOP
 *
 * Timing: Timer1 runs free at 16 MHz / 8 = 2 MHz (tick 0.5 us), extended to
 * 32 bits by its overflow interrupt. Each channel keeps the timer value of its
 * next edge; the Timer1 compare-A interrupt toggles every channel whose edge
 * is due and programs OCR1A for the earliest remaining edge (or for an
 * intermediate wake-up 15 ms ahead when that edge is further away). Edge times are
 * computed from the previous *scheduled* edge, never from the time the ISR
 * ran, so ISR latency does not accumulate: long-run period accuracy is that
 * of the 16 MHz crystal/resonator. See PROTOCOL.md, "Limits and timing".
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "proto.h"

#define BAUD 115200UL
#define TICKS_PER_US 2UL
/* Edges due within this many ticks are output in the same ISR pass. */
#define DUE_WINDOW_TICKS 8
#define OUT_MASK 0xF0 /* PD4..PD7 */
#define OUT_SHIFT 4

struct chan_rt {
    uint32_t next;      /* timer tick of the next edge */
    uint32_t high_t;    /* width in ticks */
    uint32_t low_t;     /* period - width in ticks */
    uint32_t remaining; /* pulses left, 0 = continuous */
    uint8_t level;
    uint8_t active;
};

static volatile struct chan_rt rt[CHANNELS];
static volatile struct led_chan armed_cfg[CHANNELS];
static volatile uint8_t armed_mask;
static volatile uint8_t armed_mode;
static volatile uint8_t fired;
static volatile uint32_t t0_ticks;
static volatile uint16_t ovf_hi;

/* ---------------------------------------------------------------- time */

/* 32-bit tick count. Call with interrupts disabled. */
static uint32_t now_ticks_locked(void)
{
    uint16_t lo = TCNT1;
    uint16_t hi = ovf_hi;
    if ((TIFR1 & _BV(TOV1)) && lo < 0x8000)
        hi++; /* overflow pending, not yet counted */
    return ((uint32_t)hi << 16) | lo;
}

/* Outputs every edge that is due; returns when none is. */
static void service_due_locked(void)
{
    for (;;) {
        uint32_t now = now_ticks_locked();
        uint8_t set = 0, clr = 0;
        for (uint8_t c = 0; c < CHANNELS; c++) {
            volatile struct chan_rt *r = &rt[c];
            if (!r->active)
                continue;
            if ((int32_t)(r->next - now) > DUE_WINDOW_TICKS)
                continue;
            if (!r->level) {
                set |= (uint8_t)(1u << (c + OUT_SHIFT));
                r->level = 1;
                r->next += r->high_t;
            } else {
                clr |= (uint8_t)(1u << (c + OUT_SHIFT));
                r->level = 0;
                r->next += r->low_t;
                if (r->remaining && --r->remaining == 0)
                    r->active = 0;
            }
        }
        if (!set && !clr)
            return;
        PORTD = (uint8_t)((PORTD | set) & ~clr);
    }
}

/* Programs OCR1A for the earliest pending edge. Returns 1 if an edge became
 * due meanwhile (the caller services and calls again). */
static uint8_t schedule_locked(void)
{
    uint8_t any = 0;
    uint32_t best = 0;
    uint32_t now = now_ticks_locked();
    int32_t best_d = 0x7FFFFFFF;
    for (uint8_t c = 0; c < CHANNELS; c++) {
        if (!rt[c].active)
            continue;
        int32_t d = (int32_t)(rt[c].next - now);
        if (!any || d < best_d) {
            best_d = d;
            best = rt[c].next;
            any = 1;
        }
    }
    TIMSK1 &= (uint8_t)~_BV(OCIE1A);
    if (!any)
        return 0;
    if (best_d <= DUE_WINDOW_TICKS)
        return 1;
    /* Far edges (beyond one 16-bit timer window) get an intermediate wake-up. */
    uint32_t target = best_d < 30000 ? best : now + 30000;
    OCR1A = (uint16_t)target;
    TIFR1 = _BV(OCF1A);
    TIMSK1 |= _BV(OCIE1A);
    /* The counter may have passed OCR1A while it was written. */
    if ((int32_t)(target - now_ticks_locked()) <= DUE_WINDOW_TICKS) {
        TIMSK1 &= (uint8_t)~_BV(OCIE1A);
        return 1;
    }
    return 0;
}

static void engine_locked(void)
{
    do
        service_due_locked();
    while (schedule_locked());
}

ISR(TIMER1_COMPA_vect) { engine_locked(); }

ISR(TIMER1_OVF_vect) { ovf_hi++; }

/* Starts the armed waveform with t = 0 at `t0`. Interrupts disabled. */
static void fire_locked(uint32_t t0)
{
    if (fired)
        return;
    EIMSK &= (uint8_t)~_BV(INT0);
    t0_ticks = t0;
    for (uint8_t c = 0; c < CHANNELS; c++) {
        volatile struct chan_rt *r = &rt[c];
        r->active = (uint8_t)((armed_mask >> c) & 1u);
        r->level = 0;
        r->next = t0 + armed_cfg[c].phase_us * TICKS_PER_US;
        r->high_t = armed_cfg[c].width_us * TICKS_PER_US;
        r->low_t = (armed_cfg[c].period_us - armed_cfg[c].width_us) * TICKS_PER_US;
        r->remaining = armed_cfg[c].count;
    }
    fired = 1;
    engine_locked();
}

ISR(INT0_vect)
{
    /* Timestamp first: this is t = 0 of the waveform. */
    uint32_t t = now_ticks_locked();
    fire_locked(t);
}

/* ---------------------------------------------------------------- HAL */

void hal_arm(uint8_t mode, const struct led_chan *cfg, uint8_t mask)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        for (uint8_t c = 0; c < CHANNELS; c++) {
            armed_cfg[c].period_us = cfg[c].period_us;
            armed_cfg[c].width_us = cfg[c].width_us;
            armed_cfg[c].phase_us = cfg[c].phase_us;
            armed_cfg[c].count = cfg[c].count;
            rt[c].active = 0;
        }
        PORTD &= (uint8_t)~OUT_MASK;
        armed_mask = mask;
        armed_mode = mode;
        fired = 0;
        EIMSK &= (uint8_t)~_BV(INT0);
        if (mode == ARM_RISE || mode == ARM_FALL) {
            /* ISC01:ISC00 = 11 rising, 10 falling. */
            EICRA = (uint8_t)((EICRA & ~(_BV(ISC01) | _BV(ISC00))) | _BV(ISC01) |
                              (mode == ARM_RISE ? _BV(ISC00) : 0));
            EIFR = _BV(INTF0); /* forget edges seen before arming */
            EIMSK |= _BV(INT0);
        }
        PORTB |= _BV(PB5);
    }
}

void hal_fire(void)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { fire_locked(now_ticks_locked()); }
}

uint8_t hal_fired(void) { return fired; }

uint8_t hal_running(void)
{
    uint8_t any = 0;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        for (uint8_t c = 0; c < CHANNELS; c++)
            any |= rt[c].active;
    }
    return any;
}

uint32_t hal_elapsed_us(void)
{
    uint32_t d;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { d = now_ticks_locked() - t0_ticks; }
    return d / TICKS_PER_US;
}

void hal_stop(void)
{
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        EIMSK &= (uint8_t)~_BV(INT0);
        TIMSK1 &= (uint8_t)~_BV(OCIE1A);
        for (uint8_t c = 0; c < CHANNELS; c++)
            rt[c].active = 0;
        PORTD &= (uint8_t)~OUT_MASK;
        fired = 0;
        PORTB &= (uint8_t)~_BV(PB5);
    }
}

void hal_write(const char *s, uint8_t n)
{
    while (n--) {
        while (!(UCSR0A & _BV(UDRE0)))
            ;
        UDR0 = (uint8_t)*s++;
    }
}

/* ---------------------------------------------------------------- UART RX */

#define RX_SIZE 128 /* power of two */
static volatile uint8_t rx_buf[RX_SIZE];
static volatile uint8_t rx_head, rx_tail;

ISR(USART_RX_vect)
{
    uint8_t status = UCSR0A;
    uint8_t b = UDR0;
    if (status & (_BV(FE0) | _BV(DOR0)))
        b = 0x00; /* damaged byte: inject a non-printable so the line fails framing */
    uint8_t next = (uint8_t)((rx_head + 1) & (RX_SIZE - 1));
    if (next != rx_tail) {
        rx_buf[rx_head] = b;
        rx_head = next;
    }
    /* On overflow the byte is lost; the line then fails its checksum. */
}

static void uart_init(void)
{
    /* U2X: UBRR = F_CPU / (8 * BAUD) - 1 = 16 -> 117647 baud (+2.1 %), the Arduino default. */
    UCSR0A = _BV(U2X0);
    UBRR0 = (uint16_t)(F_CPU / (8UL * BAUD) - 1);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

int main(void)
{
    DDRD |= OUT_MASK;
    PORTD &= (uint8_t)~OUT_MASK;
    DDRD &= (uint8_t)~_BV(PD2);
    PORTD &= (uint8_t)~_BV(PD2); /* no pull-up: driven by the camera's output */
    DDRB |= _BV(PB5);

    TCCR1A = 0;
    TCCR1B = _BV(CS11); /* normal mode, clk/8 */
    TIMSK1 = _BV(TOIE1);

    uart_init();
    proto_init();
    sei();

    for (;;) {
        while (rx_tail != rx_head) {
            uint8_t b = rx_buf[rx_tail];
            rx_tail = (uint8_t)((rx_tail + 1) & (RX_SIZE - 1));
            proto_feed(b);
        }
    }
}
