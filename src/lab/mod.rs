//! The bench: the live pipeline ([`pipeline`]: acquisition, raw writer, reconstruction
//! workers, session file, and a session assembled from plain data), the live page
//! ([`live`]) and the result viewer it serves ([`viewer`], files read through
//! [`folder_files`]), opening any camera a spec names ([`camera`]), recording a capture
//! folder from a camera ([`record`]), the simulated camera backend ([`simcam`]),
//! simulated captures written as a bench gives them ([`sim_output`]), the LED pulse
//! controller ([`led`]), the second, global-shutter key-frame camera ([`keycam`]), the LED sweep on the bench ([`led_sweep`]), and [`hardware`],
//! the one mapping between the hardware crate's types and the model's.

pub mod camera;
pub mod folder_files;
pub mod hardware;
pub mod keycam;
pub mod led;
pub mod led_sweep;
pub mod live;
pub mod pipeline;
pub mod record;
pub mod sim_output;
pub mod simcam;
pub mod viewer;
