//! What the integration tests share, written once and included by every test binary
//! (`#[path = "../support/mod.rs"] mod support;`); a test file names the part it uses
//! (`use crate::support::cli;`).

pub mod browser;
pub mod cli;
pub mod common;
pub mod hostile;
pub mod pipeline_common;
