//! The commands, one file each. They parse, validate once, call the library and
//! report; flag groups shared by several commands (capture description, solver,
//! progress) live in [`common`].

pub mod analyze;
pub mod bench;
pub mod calibrate;
pub mod capture;
pub mod common;
pub mod compare;
pub mod demo;
pub mod devices;
pub mod experiment;
pub mod led;
pub mod reconstruct;
pub mod run;
pub mod sequence;
pub mod serve;
pub mod simulate;
pub mod view;
