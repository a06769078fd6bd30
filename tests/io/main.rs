//! The file-format layer: round trips, figures, and hostile files. One test binary
//! (`cargo test --test io`).

#[path = "../support/mod.rs"]
mod support;

mod hostile_files;
mod io_figures;
mod io_roundtrip;
mod raw_files;
