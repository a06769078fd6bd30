//! The bench: the live pipeline ([`pipeline`]: acquisition, raw writer, reconstruction
//! workers, session file, and a session assembled from plain data), the live page
//! ([`live`]), the simulated cameras' renderers ([`simcam`]), simulated captures
//! written as a bench gives them ([`sim_output`]), and [`hardware`], the one mapping
//! between the hardware crate's types and the model's.

pub mod hardware;
pub mod live;
pub mod pipeline;
pub mod sim_output;
pub mod simcam;
