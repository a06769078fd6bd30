//! The camera data types: settings requested and applied, sensor geometry and
//! capabilities, identity, and the frames with their metadata. Plain data (serde), no
//! device access; the capture folder ([`crate::capture`]) records them, and the hardware
//! crate's cameras (re-exported there as `rollcam_hw::camera::types`) produce them.

use std::fmt;
use std::str::FromStr;
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

/// Shutter (readout) mode of the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CameraShutter {
    Global,
    Rolling,
    /// Alternating / dual readout (vendor specific, e.g. two halves read in opposite directions).
    Dual,
}

impl CameraShutter {
    pub const ALL: [CameraShutter; 3] = [CameraShutter::Global, CameraShutter::Rolling, CameraShutter::Dual];
    pub fn as_str(self) -> &'static str {
        match self {
            CameraShutter::Global => "global",
            CameraShutter::Rolling => "rolling",
            CameraShutter::Dual => "dual",
        }
    }
}

impl fmt::Display for CameraShutter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for CameraShutter {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "global" => Ok(CameraShutter::Global),
            "rolling" => Ok(CameraShutter::Rolling),
            "dual" => Ok(CameraShutter::Dual),
            other => Err(format!("shutter mode '{other}': expected global, rolling or dual")),
        }
    }
}

/// Pixel format of the transferred image. Frames are always delivered as
/// `u16` samples; `bit_depth` says how many of the low bits are significant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum PixelFormat {
    Mono8,
    Mono10,
    Mono12,
    Mono14,
    Mono16,
}

impl PixelFormat {
    pub fn bit_depth(self) -> u8 {
        match self {
            PixelFormat::Mono8 => 8,
            PixelFormat::Mono10 => 10,
            PixelFormat::Mono12 => 12,
            PixelFormat::Mono14 => 14,
            PixelFormat::Mono16 => 16,
        }
    }
    /// Bytes per pixel on the wire (unpacked formats only).
    pub fn bytes_per_pixel(self) -> usize {
        if self == PixelFormat::Mono8 {
            1
        } else {
            2
        }
    }
    /// GenICam PFNC name.
    pub fn genicam_name(self) -> &'static str {
        match self {
            PixelFormat::Mono8 => "Mono8",
            PixelFormat::Mono10 => "Mono10",
            PixelFormat::Mono12 => "Mono12",
            PixelFormat::Mono14 => "Mono14",
            PixelFormat::Mono16 => "Mono16",
        }
    }
    pub fn from_genicam_name(name: &str) -> Option<PixelFormat> {
        match name {
            "Mono8" => Some(PixelFormat::Mono8),
            "Mono10" => Some(PixelFormat::Mono10),
            "Mono12" => Some(PixelFormat::Mono12),
            "Mono14" => Some(PixelFormat::Mono14),
            "Mono16" => Some(PixelFormat::Mono16),
            _ => None,
        }
    }
}

impl fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.genicam_name())
    }
}

impl FromStr for PixelFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let canon = match s.to_ascii_lowercase().as_str() {
            "mono8" => "Mono8",
            "mono10" => "Mono10",
            "mono12" => "Mono12",
            "mono14" => "Mono14",
            "mono16" => "Mono16",
            _ => "",
        };
        PixelFormat::from_genicam_name(canon).ok_or_else(|| format!("pixel format '{s}': expected Mono8, Mono10, Mono12, Mono14 or Mono16"))
    }
}

/// Edge of a hardware trigger signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Edge {
    Rising,
    Falling,
    Any,
}

impl FromStr for Edge {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "rising" => Ok(Edge::Rising),
            "falling" => Ok(Edge::Falling),
            "any" | "both" => Ok(Edge::Any),
            other => Err(format!("trigger edge '{other}': expected rising, falling or any")),
        }
    }
}

/// What starts a frame.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case")]
pub enum Trigger {
    /// The camera runs at its own frame rate.
    FreeRun,
    /// One frame per `Camera::software_trigger` call (`rollcam_hw::camera`).
    Software,
    /// One frame per edge on a hardware input line (e.g. `Line0`).
    Hardware { line: String, edge: Edge },
}

impl fmt::Display for Trigger {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Trigger::FreeRun => f.write_str("free-run"),
            Trigger::Software => f.write_str("software"),
            Trigger::Hardware { line, edge } => write!(f, "hardware:{line}:{edge:?}"),
        }
    }
}

impl FromStr for Trigger {
    type Err = String;
    /// `free-run` | `software` | `hardware:<line>[:rising|falling|any]`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.to_ascii_lowercase();
        match lower.as_str() {
            "free-run" | "freerun" | "free_run" | "off" => return Ok(Trigger::FreeRun),
            "software" | "sw" => return Ok(Trigger::Software),
            _ => {}
        }
        let mut parts = s.split(':');
        match parts.next().map(|p| p.to_ascii_lowercase()) {
            Some(ref p) if p == "hardware" || p == "hw" => {
                let line = parts
                    .next()
                    .filter(|l| !l.is_empty())
                    .ok_or_else(|| format!("trigger '{s}': expected hardware:<line>[:edge], e.g. hardware:Line0:rising"))?;
                let edge = match parts.next() {
                    Some(e) => e.parse()?,
                    None => Edge::Rising,
                };
                Ok(Trigger::Hardware { line: line.to_string(), edge })
            }
            _ => Err(format!("trigger '{s}': expected free-run, software or hardware:<line>[:rising|falling|any]")),
        }
    }
}

/// Region of interest on the sensor, in sensor pixels (before binning).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Roi {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl FromStr for Roi {
    type Err = String;
    /// `x,y,width,height` or `WIDTHxHEIGHT+X+Y`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = || format!("ROI '{s}': expected x,y,width,height (e.g. 0,0,640,480) or WxH+X+Y");
        let nums: Vec<u32> = if s.contains(',') {
            s.split(',').map(|p| p.trim().parse().map_err(|_| err())).collect::<Result<_, _>>()?
        } else {
            let (wh, rest) = s.split_once('+').ok_or_else(err)?;
            let (w, h) = wh.split_once('x').ok_or_else(err)?;
            let (x, y) = rest.split_once('+').ok_or_else(err)?;
            let p = |v: &str| v.trim().parse::<u32>().map_err(|_| err());
            vec![p(x)?, p(y)?, p(w)?, p(h)?]
        };
        if nums.len() != 4 {
            return Err(err());
        }
        Ok(Roi { x: nums[0], y: nums[1], width: nums[2], height: nums[3] })
    }
}

/// Binning factors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Binning {
    pub horizontal: u32,
    pub vertical: u32,
}

impl Default for Binning {
    fn default() -> Self {
        Binning { horizontal: 1, vertical: 1 }
    }
}

/// Settings requested by the user. `None` leaves the device's current value.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraSettings {
    pub exposure_us: Option<f64>,
    /// Row-to-row delay of a rolling shutter.
    pub line_time_us: Option<f64>,
    pub frame_rate_hz: Option<f64>,
    pub shutter: Option<CameraShutter>,
    pub roi: Option<Roi>,
    pub binning: Option<Binning>,
    pub pixel_format: Option<PixelFormat>,
    pub trigger: Option<Trigger>,
    /// Route the exposure-active signal to this output line (e.g. `Line1`), to drive the LED pulser.
    pub exposure_output_line: Option<String>,
}

/// Settings as read back from the device.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AppliedSettings {
    pub exposure_us: f64,
    pub line_time_us: Option<f64>,
    pub frame_rate_hz: Option<f64>,
    pub shutter: Option<CameraShutter>,
    pub roi: Roi,
    pub binning: Binning,
    pub pixel_format: PixelFormat,
    pub trigger: Trigger,
    pub exposure_output_line: Option<String>,
}

impl AppliedSettings {
    /// Image size delivered by the camera after binning.
    pub fn image_size(&self) -> (u32, u32) {
        (self.roi.width / self.binning.horizontal.max(1), self.roi.height / self.binning.vertical.max(1))
    }
}

/// Full sensor geometry.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorGeometry {
    pub width: u32,
    pub height: u32,
    /// Largest bit depth the sensor delivers.
    pub max_bit_depth: u8,
}

/// Ranges and choices the device reports. `None` ranges mean "not available".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Capabilities {
    pub exposure_range_us: Option<(f64, f64)>,
    pub line_time_range_us: Option<(f64, f64)>,
    pub frame_rate_range_hz: Option<(f64, f64)>,
    pub shutter_modes: Vec<CameraShutter>,
    pub pixel_formats: Vec<PixelFormat>,
    pub max_binning: Binning,
    pub software_trigger: bool,
    pub hardware_trigger_lines: Vec<String>,
}

/// Identity of a camera as discovered.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Backend name: `aravis`, `replay`, `sim`.
    pub backend: String,
    /// Id to open the camera with, unique within the backend.
    pub id: String,
    pub vendor: Option<String>,
    pub model: Option<String>,
    pub serial: Option<String>,
    /// Transport address (IP, USB bus/port, folder).
    pub address: Option<String>,
    pub protocol: Option<String>,
}

impl CameraInfo {
    /// `backend:id`, the form accepted by `rollcam_hw::camera::CameraSpec`.
    pub fn spec(&self) -> String {
        format!("{}:{}", self.backend, self.id)
    }
}

/// Outcome of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameStatus {
    Complete,
    /// Some data arrived but not all (lost packets, truncated buffer). The
    /// valid prefix is `meta.valid_pixels` long.
    Incomplete,
    /// The frame was announced by the frame counter but never arrived; no pixels.
    Dropped,
}

/// Metadata carried by every frame. Serialised as the recorder's sidecar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameMeta {
    /// `backend:id` of the source camera.
    pub camera: String,
    /// Frame counter from the device.
    pub frame_id: u64,
    /// Position in this acquisition (0, 1, 2, ... including dropped frames).
    pub sequence: u64,
    /// Device timestamp (ns, device clock). 0 when the device gives none.
    pub device_timestamp_ns: u64,
    /// Host arrival time, ns since the Unix epoch.
    pub host_timestamp_ns: u64,
    pub status: FrameStatus,
    pub width: u32,
    pub height: u32,
    pub bit_depth: u8,
    /// Number of valid samples in `pixels` (= width*height when complete).
    pub valid_pixels: u64,
    pub settings: AppliedSettings,
}

/// A frame of 16-bit samples, row-major, `width * height` long when complete.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub meta: FrameMeta,
    pub pixels: Vec<u16>,
}

/// Host clock in ns since the Unix epoch (frames' and capture sessions' host times).
pub fn host_now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_cli_values() {
        assert_eq!("10,20,640,480".parse::<Roi>().unwrap(), Roi { x: 10, y: 20, width: 640, height: 480 });
        assert_eq!("640x480+10+20".parse::<Roi>().unwrap(), Roi { x: 10, y: 20, width: 640, height: 480 });
        assert!("640x480".parse::<Roi>().is_err());
        assert_eq!("hardware:Line0:falling".parse::<Trigger>().unwrap(), Trigger::Hardware { line: "Line0".into(), edge: Edge::Falling });
        assert_eq!("software".parse::<Trigger>().unwrap(), Trigger::Software);
        assert!("hardware".parse::<Trigger>().is_err());
        assert_eq!("Rolling".parse::<CameraShutter>().unwrap(), CameraShutter::Rolling);
    }
}
