//! The bench: the live pipeline ([`pipeline`]: acquisition, raw writer, reconstruction
//! workers, session file), the live page ([`live`]), the simulated camera's renderer
//! ([`simcam`]), and [`hardware`], the one mapping between the hardware crate's types
//! and the model's.

pub mod hardware;
pub mod live;
pub mod pipeline;
pub mod simcam;
