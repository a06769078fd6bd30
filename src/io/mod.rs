//! File formats and figures.
//!
//! Conventions shared with the rest of rollcam:
//! * pixel data is `f32` in memory, holding the raw counts as stored
//!   (u8 0..255 and u16 0..65535 become the same numbers; nothing is normalised);
//! * an image is `Array3<f32>` with axes (row, col, channel), 1 (grey) or 3 (RGB) channels;
//! * a video is `Array4<f32>` with axes (frame, row, col, channel).
//!
//! Every writer goes through [`write_atomic`]: the bytes go to a temporary file in the
//! destination directory, which is flushed, fsynced and renamed over the destination, so a
//! reader never sees a half-written file. Image formats are [`formats`]: one file each and
//! one registry that every image reader and writer consults. See `FORMATS.md` beside this
//! file for the formats.

mod atomic;
pub mod budget;
pub mod cache;
pub mod calibration;
pub mod capture_file;
mod display;
mod error;
mod font;
pub mod formats;
pub mod input;
pub mod out_dir;
pub mod output;
mod plot;
mod read;
pub mod sensor_files;
pub mod sequence_input;
pub mod sequence_output;
pub mod truth;
pub mod utc;
mod view_data;

pub use atomic::{write_atomic, write_text_atomic};
pub use budget::{ByteBudget, OverBudget};
pub use display::{contact_sheet_frames, write_contact_sheet, write_gif, write_png, Display, CONTACT_SHEET_MAX_FRAMES};
pub use error::IoError;
pub use formats::npy::write_npy;
pub use formats::raw::{Bayer, RawInfo};
pub use formats::tiff::{write_tiff_f32, write_tiff_stack_f32, write_tiff_u16, write_tiff_video_f32};
pub use formats::{decode_npy, read_npy};
pub use formats::{write_stack, ImageFormat, FORMATS};
pub use plot::{plot_lines, PlotSpec, Series, SERIES_COLOURS};
pub use read::{
    decode_image_bytes, decode_image_page, decode_stack_bytes, raw_info, read_image, read_image_page, read_stack, sample_black_level, sample_full_scale,
};
pub use truth::read_truth;
pub use view_data::{encode_levels_u16, VIEW_MAGIC};
