//! The device side of the LED protocol (the Rust emulator's engine): arbitrary bytes,
//! delivered in arbitrary pieces at advancing times. Every reply must be a well-formed
//! frame the host can decode.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam_hw::led::protocol::decode_frame;
use rollcam_hw::led::{Device, Identity};

fuzz_target!(|data: &[u8]| {
    let Some((&split, bytes)) = data.split_first() else { return };
    let mut device = Device::new(Identity::default());
    let mut now_us = 0u64;
    for piece in bytes.chunks(usize::from(split % 64) + 1) {
        for reply in device.feed(piece, now_us) {
            assert_eq!(reply.last(), Some(&b'\n'), "reply {reply:?}");
            decode_frame(&reply).unwrap_or_else(|e| panic!("reply {:?}: {e}", String::from_utf8_lossy(&reply)));
        }
        // Edges on the trigger input and a clock that runs on.
        if piece[0] & 0x80 != 0 {
            device.input_edge(piece[0] & 1 == 1, now_us);
        }
        now_us += u64::from(piece[0]) * 997;
        let _ = device.status(now_us);
    }
});
