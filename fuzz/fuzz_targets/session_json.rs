//! session.json as `run --resume`, `status` and the live page read it.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rollcam::lab::pipeline::session::SessionFile;

fuzz_target!(|data: &[u8]| {
    let Ok(session) = SessionFile::from_json_slice(data, "session.json") else { return };
    let json = serde_json::to_vec(&session).expect("a session read back serialises");
    assert!(SessionFile::from_json_slice(&json, "written session.json").is_ok());
});
