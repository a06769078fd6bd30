/*
 * rollcam LED pulse controller: protocol constants.
 *
 * Single source of truth for the firmware. hw/src/led/protocol.rs carries the
 * same values; the Rust test hw/tests/led/led_vectors.rs checks that they agree.
 * See PROTOCOL.md.
 */
#ifndef ROLLCAM_LED_PROTOCOL_H
#define ROLLCAM_LED_PROTOCOL_H

#define PROTOCOL_VERSION 1
#define DEVICE_NAME "rollcam-led"
#ifndef FW_VERSION
#define FW_VERSION "0.1.0"
#endif
#ifndef HW_NAME
#define HW_NAME "uno"
#endif
/* Timer1 tick at 16 MHz with prescaler 8. */
#ifndef TICK_NS
#define TICK_NS 500
#endif

/* Longest line in either direction, including '$' and the final '\n'. */
#define MAX_LINE 120
#define CHANNELS 4
#define MIN_PERIOD_US 100UL
#define MAX_PERIOD_US 10000000UL
/* Shortest high time and shortest low time within a period. */
#define MIN_WIDTH_US 10UL
#define MAX_PHASE_US 10000000UL
#define MAX_COUNT 1000000UL
#define MAX_SEQ 65535UL

/* NAK codes. */
#define E_CRC 1
#define E_FRAME 2
#define E_OVERSIZE 3
#define E_UNKNOWN 4
#define E_ARGS 5
#define E_RANGE 6
#define E_STATE 7

/* Trigger modes (ARM argument). */
#define ARM_NONE 0
#define ARM_SW 1
#define ARM_RISE 2
#define ARM_FALL 3

#endif
