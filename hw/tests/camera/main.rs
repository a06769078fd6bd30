//! The camera backends: the simulated one, the recorder and replay with fault injection,
//! GenICam through aravis' fake cameras (feature `aravis`), USB discovery (feature
//! `usb`). One test binary (`cargo test -p rollcam-hw --test camera`).

mod camera_aravis;
mod camera_record_replay;
mod camera_simulated;
mod camera_usb;
