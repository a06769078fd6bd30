//! The live bench pipeline behind `rollcam run`: every frame the camera delivers is
//! recorded raw, then reconstructed as fast as the machine allows.
//!
//! ```text
//!  camera ──► acquisition ──(unbounded)──► writer ──(bounded work queue)──► workers ──► rec/frame_N/
//!             (acquire.rs)                 raw/ first                      (worker.rs)
//!                                          backlog of ids on disk ─┘
//!  ticker (this thread): session.json + preview/*.png, Ctrl-C
//! ```
//!
//! * Acquisition never waits: frames go to the writer over an unbounded channel.
//! * The writer records each raw frame durably (TIFF + sidecar) before anything else
//!   sees it, then queues its id. When the bounded work queue (`queue`) is full,
//!   `catch-up` keeps the id in an in-memory backlog (the frame itself is on disk) and
//!   the workers take it later, in order; `live` skips the oldest queued frame instead,
//!   so the workers always work on recent frames.
//! * Workers call one [`worker::FrameReconstructor`] per frame, inside
//!   `catch_unwind`: a panic fails that frame only.
//! * Stopping (`frames`, Ctrl-C, a camera fault, a full disk): acquisition stops, the
//!   writer records what it already has, the workers drain the queue. A second Ctrl-C
//!   abandons the drain: what is left stays listed in `session.json` (`pending`) and
//!   [`resume`] reconstructs it later.
//!
//! One file per part, re-exported here: [`folder`] (layout, creation), [`options`],
//! `shared` (the threads' shared state), [`driver`] ([`run`], [`resume`]),
//! [`acquire`], [`writer`], [`worker`], [`consecutive`] (the continuous video),
//! [`session`] (`session.json`), [`preview`] and [`setup`] (a session assembled from
//! plain data).

pub mod acquire;
pub mod consecutive;
pub mod driver;
pub mod folder;
pub mod lock;
pub mod options;
pub mod preview;
pub mod session;
pub mod setup;
pub(crate) mod shared;
pub mod worker;
pub mod writer;

pub use driver::{resume, run};
pub use folder::{check_new_folder, create_folder, PsfInput, CAPTURE_TOML, PSF_TIFF, RAW_DIR, REC_DIR};
pub use options::{Options, Policy, TestHooks};
