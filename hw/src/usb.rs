//! USB discovery of cameras and LED controllers through the system libusb (`rusb`).
//!
//! Uses an explicit [`rusb::Context`]. A machine without a USB bus (e.g. a
//! container without `/dev/bus/usb`) yields [`UsbError::NoBus`], not a panic.

use serde::{Deserialize, Serialize};

use rusb::UsbContext;

/// What kind of bench device a USB device looks like.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UsbDeviceKind {
    /// Camera from a known vendor or exposing the USB3 Vision interface class.
    Camera,
    /// Microcontroller / USB-serial bridge that may drive the LED pulser.
    LedController,
}

/// Known vendor ids: (vendor id, vendor name, kind).
pub const KNOWN_VENDORS: &[(u16, &str, UsbDeviceKind)] = &[
    (0x2676, "Basler", UsbDeviceKind::Camera),
    (0x1e10, "FLIR / Point Grey", UsbDeviceKind::Camera),
    (0x1cb2, "PCO", UsbDeviceKind::Camera),
    (0x1ab2, "Allied Vision", UsbDeviceKind::Camera),
    (0x1409, "IDS Imaging", UsbDeviceKind::Camera),
    (0x20f7, "XIMEA", UsbDeviceKind::Camera),
    (0x2341, "Arduino", UsbDeviceKind::LedController),
    (0x2a03, "Arduino (arduino.org)", UsbDeviceKind::LedController),
    (0x0403, "FTDI", UsbDeviceKind::LedController),
    (0x1a86, "QinHeng (CH340)", UsbDeviceKind::LedController),
    (0x10c4, "Silicon Labs (CP210x)", UsbDeviceKind::LedController),
    (0x16c0, "Van Ooijen / PJRC (Teensy)", UsbDeviceKind::LedController),
];

/// USB3 Vision: interface class 0xEF (miscellaneous), subclass 0x05.
pub const USB3_VISION_CLASS: (u8, u8) = (0xef, 0x05);

/// A USB device that looks like a camera or an LED controller.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct UsbDeviceInfo {
    pub kind: UsbDeviceKind,
    pub vendor_id: u16,
    pub product_id: u16,
    pub vendor_name: Option<String>,
    pub bus: u8,
    pub address: u8,
    /// Port path from the root hub, e.g. `1-2.3` style as a list `[2, 3]`.
    pub ports: Vec<u8>,
    /// The device exposes a USB3 Vision interface.
    pub usb3_vision: bool,
}

impl UsbDeviceInfo {
    /// `bus-port.port...`, the sysfs-style location.
    pub fn location(&self) -> String {
        let ports: Vec<String> = self.ports.iter().map(|p| p.to_string()).collect();
        if ports.is_empty() {
            format!("{}:{}", self.bus, self.address)
        } else {
            format!("{}-{}", self.bus, ports.join("."))
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum UsbError {
    #[error("no USB bus found: {0}")]
    NoBus(String),
    #[error("USB: {context}: {source}")]
    Usb { context: String, source: rusb::Error },
}

/// Classify a device from its descriptor fields.
pub fn classify(vendor_id: u16, usb3_vision: bool) -> Option<(UsbDeviceKind, Option<&'static str>)> {
    let known = KNOWN_VENDORS.iter().find(|(v, _, _)| *v == vendor_id);
    match (known, usb3_vision) {
        (_, true) => Some((UsbDeviceKind::Camera, known.map(|k| k.1))),
        (Some((_, name, kind)), false) => Some((*kind, Some(*name))),
        (None, false) => None,
    }
}

/// Open a libusb context, mapping "no bus" failures to [`UsbError::NoBus`].
pub fn context() -> Result<rusb::Context, UsbError> {
    rusb::Context::new().map_err(|e| UsbError::NoBus(format!("libusb initialisation failed ({e})")))
}

/// List USB devices that look like cameras or LED controllers.
pub fn discover() -> Result<Vec<UsbDeviceInfo>, UsbError> {
    let ctx = context()?;
    discover_with(&ctx)
}

/// As [`discover`], with a caller-provided context.
pub fn discover_with(ctx: &rusb::Context) -> Result<Vec<UsbDeviceInfo>, UsbError> {
    let list = ctx.devices().map_err(|e| match e {
        rusb::Error::Access | rusb::Error::NoDevice | rusb::Error::NotFound | rusb::Error::Io | rusb::Error::Other => {
            UsbError::NoBus(format!("cannot list devices ({e})"))
        }
        source => UsbError::Usb { context: "listing devices".into(), source },
    })?;
    if list.is_empty() && !std::path::Path::new("/dev/bus/usb").exists() && cfg!(target_os = "linux") {
        return Err(UsbError::NoBus("/dev/bus/usb does not exist and libusb sees no devices".into()));
    }
    let mut out = Vec::new();
    for dev in list.iter() {
        let desc = match dev.device_descriptor() {
            Ok(d) => d,
            Err(e) => {
                tracing::debug!(bus = dev.bus_number(), address = dev.address(), error = %e, "skipping device without descriptor");
                continue;
            }
        };
        let usb3_vision = dev
            .active_config_descriptor()
            .or_else(|_| dev.config_descriptor(0))
            .map(|cfg| cfg.interfaces().any(|i| i.descriptors().any(|d| (d.class_code(), d.sub_class_code()) == USB3_VISION_CLASS)))
            .unwrap_or(false);
        if let Some((kind, vendor_name)) = classify(desc.vendor_id(), usb3_vision) {
            out.push(UsbDeviceInfo {
                kind,
                vendor_id: desc.vendor_id(),
                product_id: desc.product_id(),
                vendor_name: vendor_name.map(str::to_string),
                bus: dev.bus_number(),
                address: dev.address(),
                ports: dev.port_numbers().unwrap_or_default(),
                usb3_vision,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classification_uses_vendor_ids_and_usb3_vision_class() {
        assert_eq!(classify(0x2676, false).unwrap().0, UsbDeviceKind::Camera);
        assert_eq!(classify(0x2341, false).unwrap().0, UsbDeviceKind::LedController);
        assert_eq!(classify(0x1a86, false).unwrap().1, Some("QinHeng (CH340)"));
        assert_eq!(classify(0xdead, true).unwrap(), (UsbDeviceKind::Camera, None));
        assert!(classify(0x046d, false).is_none(), "a Logitech mouse is neither");
    }

    #[test]
    fn location_is_bus_and_port_path() {
        let d = UsbDeviceInfo {
            kind: UsbDeviceKind::Camera,
            vendor_id: 0x2676,
            product_id: 1,
            vendor_name: None,
            bus: 2,
            address: 7,
            ports: vec![1, 4],
            usb3_vision: true,
        };
        assert_eq!(d.location(), "2-1.4");
    }
}
