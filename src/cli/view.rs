//! `rollcam view DIR`: the live page's video viewer over any result folder
//! (`reconstruct`, `compare`, `reconstruct-sequence`, `experiment led-sweep`, a session).

use crate::cli::common::{serve_until_ctrl_c, start_page};
use anyhow::{bail, Result};
use clap::Args;
use rollcam::lab::viewer::listing;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// The folder to view: a reconstruction (video.npy, summary.json...), a compare,
    /// sequence or LED-sweep output, a session, or a folder holding several of them.
    pub dir: PathBuf,
    /// Address to listen on; port 0 picks a free port. Keep 127.0.0.1 unless the page
    /// must be seen from other machines.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
}

pub fn run(a: ViewArgs) -> Result<()> {
    if !a.dir.is_dir() {
        bail!("{}: not a folder (expected a reconstruction, compare, sequence, sweep or session folder)", a.dir.display());
    }
    let found = listing(&a.dir).map_err(|e| anyhow::anyhow!("{}: cannot list: {e}", a.dir.display()))?;
    let server = start_page(&a.dir, a.addr)?;
    let videos = found["videos"].as_array().map_or(0, Vec::len);
    let figures = found["figures"].as_array().map_or(0, Vec::len);
    println!(
        "viewer of {} ({}, {videos} video(s), {figures} figure(s)): {}  (Ctrl-C to stop)",
        a.dir.display(),
        found["kind"].as_str().unwrap_or("folder"),
        server.url()
    );
    if found["truncated"] == true {
        println!("the folder is large: the listing stopped at its limit; view a subfolder to see the rest");
    }
    serve_until_ctrl_c(server);
    Ok(())
}
