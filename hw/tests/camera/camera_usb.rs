//! USB discovery: a machine without a USB bus is reported, not a panic.
#![cfg(feature = "usb")]

use rollcam_hw::usb::{classify, discover, UsbError};

#[test]
fn discovery_reports_missing_bus_or_lists_classified_devices() {
    let has_bus = std::path::Path::new("/dev/bus/usb").exists();
    match discover() {
        Err(UsbError::NoBus(msg)) => {
            assert!(!has_bus, "a machine with /dev/bus/usb should be listed, got: {msg}");
            let text = UsbError::NoBus(msg).to_string();
            assert!(text.starts_with("no USB bus found: "), "{text}");
        }
        Err(other) => panic!("unexpected USB error: {other}"),
        Ok(devices) => {
            assert!(has_bus || !devices.is_empty());
            for d in devices {
                let (kind, _) = classify(d.vendor_id, d.usb3_vision).expect("only classified devices are listed");
                assert_eq!(kind, d.kind);
            }
        }
    }
}
