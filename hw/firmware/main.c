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
 * next edge. The earliest edge group (edges less than 2 us apart) is
 * precomputed as port masks; the Timer1 compare-A interrupt writes them to
 * PORTD first, then advances those channels and programs OCR1A for the next
 * group (or for an intermediate wake-up 15 ms ahead when it is further away).
 * Edge times are computed from the previous *scheduled* edge, never from the
 * time the ISR ran, so latency does not accumulate. Measured in simavr
 * (sim/sim_test.c): isolated edges within 0.1 us of ideal; an edge < ~40 us
 * after another channel's is late by up to ~36 us. See PROTOCOL.md.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "proto.h"

#define BAUD 115200UL
#define TICKS_PER_US 2UL
/* Edges of different channels less than this apart are output together, at
 * the earlier one's time. */
#define GROUP_TICKS 4
/* Ticks between a trigger-input edge and the TCNT1 read in the INT0 ISR
 * (interrupt response + prologue), subtracted so that t = 0 is the edge
 * itself. Calibrated cycle-exactly in simavr (sim/sim_test.c). */
#ifndef INT0_LATENCY_TICKS
#define INT0_LATENCY_TICKS 7
#endif
/* Same for the compare ISR: the port write happens this many ticks after the
 * compare match, so the compare is programmed that much earlier. */
#ifndef OUTPUT_LATENCY_TICKS
#define OUTPUT_LATENCY_TICKS 7
#endif
#define OUT_MASK 0xF0 /* PD4..PD7 */
#define OUT_SHIFT 4

/* Channel run-time state. Touched by the ISRs; main code only inside
 * ATOMIC_BLOCK (which is a compiler barrier), hence not volatile. */
struct chan_rt {
    uint32_t next;      /* absolute timer tick of the next edge */
    uint32_t high_t;    /* width in ticks */
    uint32_t low_t;     /* period - width in ticks */
    uint32_t remaining; /* pulses left, 0 = continuous */
    uint8_t level;
    uint8_t active;
};

static struct chan_rt rt[CHANNELS];
static struct led_chan armed_cfg[CHANNELS];
static uint8_t armed_mask;
static uint8_t phase0_pins; /* outputs that rise at t = 0 */
static volatile uint8_t fired;
static uint32_t t0_ticks;
static volatile uint16_t ovf_hi;

/* The pending event: the earliest edge group, precomputed so the compare ISR
 * can write the port first and do the bookkeeping afterwards. */
static uint8_t ev_valid;
static uint8_t ev_group; /* channels in the event */
static uint8_t ev_set, ev_clr;
static uint32_t ev_abs;
static uint8_t ev_armed; /* OCR1A holds ev_abs (else an intermediate wake-up) */

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

/* Finds the earliest pending edge and the port masks of its group. */
static void plan_next(void)
{
    uint8_t any = 0;
    uint32_t best = 0;
    for (uint8_t c = 0; c < CHANNELS; c++)
        if (rt[c].active && (!any || (int32_t)(rt[c].next - best) < 0)) {
            best = rt[c].next;
            any = 1;
        }
    ev_valid = any;
    ev_group = ev_set = ev_clr = 0;
    if (!any)
        return;
    for (uint8_t c = 0; c < CHANNELS; c++)
        if (rt[c].active && (int32_t)(rt[c].next - best) < GROUP_TICKS) {
            ev_group |= (uint8_t)(1u << c);
            if (rt[c].level)
                ev_clr |= (uint8_t)(1u << (c + OUT_SHIFT));
            else
                ev_set |= (uint8_t)(1u << (c + OUT_SHIFT));
        }
    ev_abs = best;
}

/* Bookkeeping for the event just written to the port. */
static void advance_group(void)
{
    for (uint8_t c = 0; c < CHANNELS; c++) {
        if (!(ev_group & (1u << c)))
            continue;
        struct chan_rt *r = &rt[c];
        if (!r->level) {
            r->level = 1;
            r->next += r->high_t;
        } else {
            r->level = 0;
            r->next += r->low_t;
            if (r->remaining && --r->remaining == 0)
                r->active = 0;
        }
    }
}

static void output_and_advance(void)
{
    PORTD = (uint8_t)((PORTD | ev_set) & ~ev_clr);
    advance_group();
    plan_next();
}

/* Programs the compare for the pending event. Returns 1 if the event is due
 * now (after a busy-wait of at most a few ticks): the caller outputs it. */
static uint8_t arm_compare(void)
{
    ev_armed = 0;
    if (!ev_valid) {
        TIMSK1 &= (uint8_t)~_BV(OCIE1A);
        return 0;
    }
    uint32_t target = ev_abs - OUTPUT_LATENCY_TICKS;
    uint32_t now = now_ticks_locked();
    int32_t d = (int32_t)(target - now);
    if (d <= 16) {
        TIMSK1 &= (uint8_t)~_BV(OCIE1A);
        while ((int32_t)(ev_abs - now_ticks_locked()) > 0)
            ;
        return 1;
    }
    if (d < 30000) {
        ev_armed = 1;
    } else {
        target = now + 30000; /* beyond one timer window: intermediate wake-up */
    }
    OCR1A = (uint16_t)target;
    TIFR1 = _BV(OCF1A);
    TIMSK1 |= _BV(OCIE1A);
    return 0;
}

ISR(TIMER1_COMPA_vect)
{
    if (ev_armed)
        output_and_advance(); /* the port write comes first */
    while (arm_compare())
        output_and_advance();
}

ISR(TIMER1_OVF_vect) { ovf_hi++; }

/* Starts the armed waveform with t = 0 at `t0`. Interrupts disabled. The
 * outputs with phase 0 were already raised by the caller. */
static void fire_locked(uint32_t t0)
{
    EIMSK &= (uint8_t)~_BV(INT0);
    t0_ticks = t0;
    for (uint8_t c = 0; c < CHANNELS; c++) {
        struct chan_rt *r = &rt[c];
        r->active = (uint8_t)((armed_mask >> c) & 1u);
        r->level = 0;
        r->next = t0 + armed_cfg[c].phase_us * TICKS_PER_US;
        r->high_t = armed_cfg[c].width_us * TICKS_PER_US;
        r->low_t = (armed_cfg[c].period_us - armed_cfg[c].width_us) * TICKS_PER_US;
        r->remaining = armed_cfg[c].count;
        if (phase0_pins & (1u << (c + OUT_SHIFT))) {
            r->level = 1; /* rising edge at t = 0 already output */
            r->next += r->high_t;
        }
    }
    fired = 1;
    plan_next();
    while (arm_compare())
        output_and_advance();
}

ISR(INT0_vect)
{
    PORTD |= phase0_pins; /* first: edges at t = 0 */
    uint32_t t = now_ticks_locked() - INT0_LATENCY_TICKS;
    if (!fired)
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
        phase0_pins = 0;
        for (uint8_t c = 0; c < CHANNELS; c++)
            if ((mask >> c) & 1u && cfg[c].phase_us == 0)
                phase0_pins |= (uint8_t)(1u << (c + OUT_SHIFT));
        ev_valid = 0;
        ev_armed = 0;
        TIMSK1 &= (uint8_t)~_BV(OCIE1A);
        PORTD &= (uint8_t)~OUT_MASK;
        armed_mask = mask;
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
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
    {
        if (!fired) {
            PORTD |= phase0_pins;
            fire_locked(now_ticks_locked());
        }
    }
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
        ev_valid = 0;
        ev_armed = 0;
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
