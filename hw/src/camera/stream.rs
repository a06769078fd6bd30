//! Helpers for the backends' frame streams: the host clock, gap filling (skipped
//! frame ids become dropped frames) and widening raw bytes to `u16` samples.

use std::collections::VecDeque;

use rollcam_files::frame::{Frame, FrameStatus, PixelFormat};

/// The host clock lives beside the frame types (the capture folder stamps with it too).
pub use rollcam_files::frame::host_now_ns;

/// Turns a stream of frames with device frame ids into a stream where every
/// skipped id appears as a [`FrameStatus::Dropped`] frame, and assigns sequence numbers.
#[derive(Debug, Default)]
pub struct GapFiller {
    last_frame_id: Option<u64>,
    next_sequence: u64,
    pending: VecDeque<Frame>,
}

impl GapFiller {
    pub fn new() -> Self {
        Self::default()
    }

    /// Reset at the start of an acquisition.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Pop a frame queued by a previous [`GapFiller::push`].
    pub fn pop(&mut self) -> Option<Frame> {
        self.pending.pop_front()
    }

    /// Feed the next frame from the device; returns the frame to hand out now
    /// (a dropped placeholder first if ids were skipped; the rest are queued).
    pub fn push(&mut self, mut frame: Frame) -> Frame {
        if let Some(last) = self.last_frame_id {
            let id = frame.meta.frame_id;
            // Only fill modest forward gaps; a reset or wrap of the counter is not a drop.
            if id > last + 1 && id - last <= 1024 {
                for missing in last + 1..id {
                    let mut meta = frame.meta.clone();
                    meta.frame_id = missing;
                    meta.sequence = self.next_sequence;
                    self.next_sequence += 1;
                    meta.status = FrameStatus::Dropped;
                    meta.valid_pixels = 0;
                    meta.device_timestamp_ns = 0;
                    tracing::warn!(camera = %meta.camera, frame_id = missing, "frame dropped");
                    self.pending.push_back(Frame { meta, pixels: Vec::new() });
                }
            }
        }
        self.last_frame_id = Some(frame.meta.frame_id);
        frame.meta.sequence = self.next_sequence;
        self.next_sequence += 1;
        self.pending.push_back(frame);
        self.pending.pop_front().expect("just pushed")
    }
}

/// Widen raw little-endian pixel bytes to `u16` samples.
/// Returns the samples and whether the buffer was shorter than `width*height`.
pub fn bytes_to_u16(format: PixelFormat, data: &[u8], width: u32, height: u32) -> (Vec<u16>, bool) {
    let n = width as usize * height as usize;
    let samples: Vec<u16> = match format.bytes_per_pixel() {
        1 => data.iter().take(n).map(|&b| b as u16).collect(),
        _ => data.chunks_exact(2).take(n).map(|c| u16::from_le_bytes([c[0], c[1]])).collect(),
    };
    let short = samples.len() < n;
    (samples, short)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_handles_short_buffers() {
        let (px, short) = bytes_to_u16(PixelFormat::Mono16, &[1, 2, 3, 4, 5], 2, 2);
        assert_eq!(px, vec![0x0201, 0x0403]);
        assert!(short);
        let (px, short) = bytes_to_u16(PixelFormat::Mono8, &[1, 2, 3, 4], 2, 2);
        assert_eq!(px, vec![1, 2, 3, 4]);
        assert!(!short);
    }
}
