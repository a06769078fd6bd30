//! Analysis of reconstructed videos: time courses of regions and their agreement with
//! a known waveform ([`region_time_course`], [`correlation`]), what the timing predicts
//! ([`theory`]), temporal power spectra in Hz ([`spectrum`]), projections, spots and
//! spatial dips ([`video`]), the whole `analyze` pipeline ([`report`]) and what it
//! reads ([`input`]), the simulated LED sweep experiment ([`led_sweep`]), the
//! folder of a solver comparison ([`compare`]), a bench calibration from its dark
//! frames, point-source shots and background frames ([`calibrate`]), the check of
//! point-source shots as they are taken ([`psf_check`]), and the metrics
//! of a dense scene (a moving object over a static texture): its static image and its
//! object track against the truth's ([`track`]).

pub mod calibrate;
pub mod compare;
mod course;
pub mod input;
pub mod led_sweep;
pub mod psf_check;
pub mod report;
pub mod spectrum;
pub mod theory;
pub mod track;
pub mod video;

pub use course::{correlation, courses_against_truth, region_time_course, CourseAgainstTruth};
