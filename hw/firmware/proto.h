/* Portable protocol engine: line assembly, checksum, parsing, state machine.
 * Compiled into the firmware (main.c) and into host_test.c. */
#ifndef ROLLCAM_LED_PROTO_H
#define ROLLCAM_LED_PROTO_H
#include <stdint.h>
#include "protocol.h"

struct led_chan {
    uint32_t period_us;
    uint32_t width_us;
    uint32_t phase_us;
    uint32_t count; /* 0 = continuous */
};

/* ---- provided by the platform (main.c on AVR, host_test.c on a PC) ---- */
/* Prepare outputs for `cfg` (channels set in `mask`) and listen for `mode`
 * (ARM_SW: only hal_fire; ARM_RISE / ARM_FALL: the trigger input too). */
void hal_arm(uint8_t mode, const struct led_chan *cfg, uint8_t mask);
/* Software trigger: start the prepared waveform now. */
void hal_fire(void);
/* Non-zero once the armed waveform has started (by hal_fire or the input). */
uint8_t hal_fired(void);
/* Non-zero while some channel still has pulses to produce. */
uint8_t hal_running(void);
/* Microseconds since the trigger (saturating). */
uint32_t hal_elapsed_us(void);
/* All outputs low, trigger input ignored. */
void hal_stop(void);
/* Send bytes to the host. */
void hal_write(const char *s, uint8_t n);

/* ---- engine ---- */
void proto_init(void);
void proto_feed(uint8_t byte);
uint8_t proto_crc8(const uint8_t *p, uint8_t n);

#endif
