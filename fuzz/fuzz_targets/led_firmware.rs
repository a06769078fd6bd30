//! The device side of the LED protocol in the firmware's own C engine
//! (hw/firmware/proto.c, compiled by build.rs): arbitrary bytes fed one at a time. Every
//! reply must be a well-formed frame the host can decode, and no reply may be longer
//! than a protocol line.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam_hw::led::protocol::{decode_frame, MAX_LINE};
use std::cell::RefCell;

extern "C" {
    fn proto_init();
    fn proto_feed(byte: u8);
}

#[repr(C)]
pub struct LedChan {
    period_us: u32,
    width_us: u32,
    phase_us: u32,
    count: u32,
}

thread_local! {
    static WRITTEN: RefCell<Vec<u8>> = const { RefCell::new(Vec::new()) };
    static FIRED: RefCell<u8> = const { RefCell::new(0) };
}

// The platform of proto.h, as host_test.c has it: a clock at t = 0 and a waveform
// that runs until STOP.
#[no_mangle]
pub extern "C" fn hal_arm(_mode: u8, _cfg: *const LedChan, _mask: u8) {
    FIRED.with(|f| *f.borrow_mut() = 0);
}
#[no_mangle]
pub extern "C" fn hal_fire() {
    FIRED.with(|f| *f.borrow_mut() = 1);
}
#[no_mangle]
pub extern "C" fn hal_fired() -> u8 {
    FIRED.with(|f| *f.borrow())
}
#[no_mangle]
pub extern "C" fn hal_running() -> u8 {
    FIRED.with(|f| *f.borrow())
}
#[no_mangle]
pub extern "C" fn hal_elapsed_us() -> u32 {
    0
}
#[no_mangle]
pub extern "C" fn hal_stop() {
    FIRED.with(|f| *f.borrow_mut() = 0);
}
/// # Safety
/// `s` points at `n` bytes (the engine's reply buffer).
#[no_mangle]
pub unsafe extern "C" fn hal_write(s: *const u8, n: u8) {
    let bytes = unsafe { std::slice::from_raw_parts(s, usize::from(n)) };
    WRITTEN.with(|w| w.borrow_mut().extend_from_slice(bytes));
}

fuzz_target!(|data: &[u8]| {
    WRITTEN.with(|w| w.borrow_mut().clear());
    FIRED.with(|f| *f.borrow_mut() = 0);
    unsafe { proto_init() };
    for &b in data {
        unsafe { proto_feed(b) };
    }
    let written = WRITTEN.with(|w| std::mem::take(&mut *w.borrow_mut()));
    for line in written.split_inclusive(|&b| b == b'\n') {
        assert!(line.len() <= MAX_LINE, "reply of {} bytes", line.len());
        assert_eq!(line.last(), Some(&b'\n'), "unterminated reply {:?}", String::from_utf8_lossy(line));
        decode_frame(line).unwrap_or_else(|e| panic!("reply {:?}: {e}", String::from_utf8_lossy(line)));
    }
});
