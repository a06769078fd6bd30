//! Performance: the reconstruction timed on synthetic presets (`rollcam bench`), with
//! the machine's memory and load.

pub mod bench;
