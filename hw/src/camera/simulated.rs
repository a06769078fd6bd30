//! Simulated camera: settings are validated and applied like a real device, frames
//! come from a pluggable [`FrameRenderer`] (e.g. the rolling-shutter simulator of
//! the main crate).

use std::time::{Duration, Instant};

use super::device::Camera;
use super::error::{check_range, CameraError};
use super::stream::host_now_ns;
use rollcam_files::frame::{
    AppliedSettings, Binning, CameraInfo, CameraSettings, CameraShutter, Capabilities, Frame, FrameMeta, FrameStatus, PixelFormat, Roi, SensorGeometry, Trigger,
};

/// Error type renderers return.
pub type RenderError = Box<dyn std::error::Error + Send + Sync>;

/// Produces the pixels of simulated frames.
pub trait FrameRenderer: Send {
    /// Full sensor size and depth of the simulated sensor.
    fn geometry(&self) -> SensorGeometry;
    /// Render frame `index` (0-based since `start`) under `settings`. Must return
    /// exactly `settings.image_size()` samples (width × height after binning).
    fn render(&mut self, index: u64, settings: &AppliedSettings) -> Result<Vec<u16>, RenderError>;
}

/// Limits and defaults of the simulated device.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedConfig {
    /// Camera id (the camera is addressed as `sim:<id>`).
    pub id: String,
    pub exposure_range_us: (f64, f64),
    pub line_time_range_us: (f64, f64),
    pub frame_rate_range_hz: (f64, f64),
    pub shutter_modes: Vec<CameraShutter>,
    pub pixel_formats: Vec<PixelFormat>,
    pub max_binning: Binning,
    /// Deliver free-run frames at the configured frame rate (true) or as fast as asked (false).
    pub real_time: bool,
    /// Settings at power-up; the ROI defaults to the full sensor.
    pub exposure_us: f64,
    pub line_time_us: f64,
    pub frame_rate_hz: f64,
    pub shutter: CameraShutter,
    pub pixel_format: PixelFormat,
}

impl Default for SimulatedConfig {
    fn default() -> Self {
        SimulatedConfig {
            id: "sim0".into(),
            exposure_range_us: (1.0, 1_000_000.0),
            line_time_range_us: (0.1, 1000.0),
            frame_rate_range_hz: (0.1, 1000.0),
            shutter_modes: vec![CameraShutter::Global, CameraShutter::Rolling],
            pixel_formats: vec![PixelFormat::Mono8, PixelFormat::Mono12, PixelFormat::Mono16],
            max_binning: Binning { horizontal: 4, vertical: 4 },
            real_time: false,
            exposure_us: 1000.0,
            line_time_us: 10.0,
            frame_rate_hz: 30.0,
            shutter: CameraShutter::Rolling,
            pixel_format: PixelFormat::Mono16,
        }
    }
}

/// A camera whose frames come from a [`FrameRenderer`].
pub struct SimulatedCamera<R: FrameRenderer> {
    info: CameraInfo,
    config: SimulatedConfig,
    renderer: R,
    settings: AppliedSettings,
    streaming: bool,
    index: u64,
    started_at: Option<Instant>,
    trigger_credits: u64,
}

impl<R: FrameRenderer> SimulatedCamera<R> {
    pub fn new(renderer: R, config: SimulatedConfig) -> Self {
        let g = renderer.geometry();
        let settings = AppliedSettings {
            exposure_us: config.exposure_us,
            line_time_us: Some(config.line_time_us),
            frame_rate_hz: Some(config.frame_rate_hz),
            shutter: Some(config.shutter),
            roi: Roi { x: 0, y: 0, width: g.width, height: g.height },
            binning: Binning::default(),
            pixel_format: config.pixel_format,
            trigger: Trigger::FreeRun,
            exposure_output_line: None,
        };
        let info = CameraInfo {
            backend: "sim".into(),
            id: config.id.clone(),
            vendor: Some("rollcam".into()),
            model: Some("simulated".into()),
            serial: None,
            address: None,
            protocol: Some("simulation".into()),
        };
        SimulatedCamera { info, config, renderer, settings, streaming: false, index: 0, started_at: None, trigger_credits: 0 }
    }

    pub fn renderer(&self) -> &R {
        &self.renderer
    }

    /// The renderer, to change what it shows between recordings.
    pub fn renderer_mut(&mut self) -> &mut R {
        &mut self.renderer
    }

    fn name(&self) -> String {
        self.info.spec()
    }

    fn unsupported(&self, setting: &str, value: String, expected: String) -> CameraError {
        CameraError::Unsupported { camera: self.name(), setting: setting.into(), value, expected }
    }

    /// Validate `req` against the device limits and return the resulting settings.
    fn validate(&self, req: &CameraSettings) -> Result<AppliedSettings, CameraError> {
        let name = self.name();
        let g = self.renderer.geometry();
        let mut s = self.settings.clone();
        if let Some(v) = req.exposure_us {
            check_range(&name, "ExposureTime", v, self.config.exposure_range_us, "us")?;
            s.exposure_us = v;
        }
        if let Some(v) = req.line_time_us {
            check_range(&name, "LineTime", v, self.config.line_time_range_us, "us")?;
            s.line_time_us = Some(v);
        }
        if let Some(v) = req.frame_rate_hz {
            check_range(&name, "AcquisitionFrameRate", v, self.config.frame_rate_range_hz, "Hz")?;
            s.frame_rate_hz = Some(v);
        }
        if let Some(v) = req.shutter {
            if !self.config.shutter_modes.contains(&v) {
                return Err(self.unsupported("shutter", v.to_string(), format!("one of {:?}", self.config.shutter_modes)));
            }
            s.shutter = Some(v);
        }
        if let Some(v) = req.pixel_format {
            if !self.config.pixel_formats.contains(&v) {
                return Err(self.unsupported("pixel_format", v.to_string(), format!("one of {:?}", self.config.pixel_formats)));
            }
            s.pixel_format = v;
        }
        if let Some(b) = req.binning {
            let m = self.config.max_binning;
            if b.horizontal == 0 || b.vertical == 0 || b.horizontal > m.horizontal || b.vertical > m.vertical {
                return Err(self.unsupported("binning", format!("{}x{}", b.horizontal, b.vertical), format!("1..={} x 1..={}", m.horizontal, m.vertical)));
            }
            s.binning = b;
        }
        if let Some(r) = req.roi {
            if r.width == 0 || r.height == 0 || r.x + r.width > g.width || r.y + r.height > g.height {
                return Err(self.unsupported(
                    "roi",
                    format!("{}x{}+{}+{}", r.width, r.height, r.x, r.y),
                    format!("a non-empty region inside the {}x{} sensor", g.width, g.height),
                ));
            }
            s.roi = r;
        }
        if let Some(t) = &req.trigger {
            if let Trigger::Hardware { .. } = t {
                return Err(self.unsupported("trigger", t.to_string(), "free-run or software (no hardware lines)".into()));
            }
            s.trigger = t.clone();
        }
        if let Some(line) = &req.exposure_output_line {
            return Err(self.unsupported("exposure_output_line", line.clone(), "none (no output lines)".into()));
        }
        let (w, h) = s.image_size();
        if w == 0 || h == 0 {
            return Err(self.unsupported("binning", format!("{:?}", s.binning), format!("a factor that leaves pixels in ROI {:?}", s.roi)));
        }
        Ok(s)
    }
}

impl<R: FrameRenderer> Camera for SimulatedCamera<R> {
    fn info(&self) -> &CameraInfo {
        &self.info
    }

    fn geometry(&mut self) -> Result<SensorGeometry, CameraError> {
        Ok(self.renderer.geometry())
    }

    fn capabilities(&mut self) -> Result<Capabilities, CameraError> {
        Ok(Capabilities {
            exposure_range_us: Some(self.config.exposure_range_us),
            line_time_range_us: Some(self.config.line_time_range_us),
            frame_rate_range_hz: Some(self.config.frame_rate_range_hz),
            shutter_modes: self.config.shutter_modes.clone(),
            pixel_formats: self.config.pixel_formats.clone(),
            max_binning: self.config.max_binning,
            software_trigger: true,
            hardware_trigger_lines: Vec::new(),
        })
    }

    fn configure(&mut self, settings: &CameraSettings) -> Result<AppliedSettings, CameraError> {
        if self.streaming {
            return Err(CameraError::State { camera: self.name(), message: "cannot configure while streaming".into() });
        }
        self.settings = self.validate(settings)?;
        Ok(self.settings.clone())
    }

    fn applied_settings(&mut self) -> Result<AppliedSettings, CameraError> {
        Ok(self.settings.clone())
    }

    fn start(&mut self) -> Result<(), CameraError> {
        self.streaming = true;
        self.index = 0;
        self.trigger_credits = 0;
        self.started_at = Some(Instant::now());
        Ok(())
    }

    fn software_trigger(&mut self) -> Result<(), CameraError> {
        if self.settings.trigger != Trigger::Software {
            return Err(CameraError::State { camera: self.name(), message: format!("software trigger sent while trigger is {}", self.settings.trigger) });
        }
        if !self.streaming {
            return Err(CameraError::State { camera: self.name(), message: "software trigger before start".into() });
        }
        self.trigger_credits += 1;
        Ok(())
    }

    fn next_frame(&mut self, timeout: Duration) -> Result<Frame, CameraError> {
        if !self.streaming {
            return Err(CameraError::State { camera: self.name(), message: "next_frame called before start".into() });
        }
        let started = self.started_at.expect("set by start");
        let period = Duration::from_secs_f64(1.0 / self.settings.frame_rate_hz.unwrap_or(self.config.frame_rate_hz));
        match self.settings.trigger {
            Trigger::Software => {
                if self.trigger_credits == 0 {
                    std::thread::sleep(timeout);
                    return Err(CameraError::Timeout { camera: self.name(), timeout_ms: timeout.as_millis() as u64 });
                }
                self.trigger_credits -= 1;
            }
            _ if self.config.real_time => {
                let due = started + period * self.index as u32;
                let now = Instant::now();
                if due > now + timeout {
                    std::thread::sleep(timeout);
                    return Err(CameraError::Timeout { camera: self.name(), timeout_ms: timeout.as_millis() as u64 });
                }
                std::thread::sleep(due.saturating_duration_since(now));
            }
            _ => {}
        }
        let index = self.index;
        let mut pixels = self.renderer.render(index, &self.settings).map_err(|e| CameraError::Render { camera: self.name(), index, message: e.to_string() })?;
        let (w, h) = self.settings.image_size();
        if pixels.len() != w as usize * h as usize {
            return Err(CameraError::Render {
                camera: self.name(),
                index,
                message: format!("renderer returned {} samples, expected {w}x{h} = {}", pixels.len(), w as u64 * h as u64),
            });
        }
        let max = ((1u32 << self.settings.pixel_format.bit_depth()) - 1) as u16;
        for p in &mut pixels {
            *p = (*p).min(max);
        }
        self.index += 1;
        let device_timestamp_ns = match self.settings.trigger {
            Trigger::FreeRun => (period * index as u32).as_nanos() as u64,
            _ => started.elapsed().as_nanos() as u64,
        };
        Ok(Frame {
            meta: FrameMeta {
                camera: self.name(),
                frame_id: index,
                sequence: index,
                device_timestamp_ns,
                host_timestamp_ns: host_now_ns(),
                status: FrameStatus::Complete,
                width: w,
                height: h,
                bit_depth: self.settings.pixel_format.bit_depth(),
                valid_pixels: pixels.len() as u64,
                settings: self.settings.clone(),
            },
            pixels,
        })
    }

    fn stop(&mut self) -> Result<(), CameraError> {
        self.streaming = false;
        Ok(())
    }
}
