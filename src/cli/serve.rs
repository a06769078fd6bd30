//! `rollcam serve SESSION_DIR`: the live page of a bench session on localhost.

use crate::cli::common::{serve_until_ctrl_c, start_page};
use anyhow::Result;
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ServeArgs {
    /// Session folder (the one `rollcam run` writes session.json and preview/ into).
    pub session_dir: PathBuf,
    /// Address to listen on; port 0 picks a free port. Keep 127.0.0.1 unless the page
    /// must be seen from other machines.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
}

pub fn run(a: ServeArgs) -> Result<()> {
    if !a.session_dir.is_dir() {
        anyhow::bail!(
            "{}: no such folder: expected a session folder (made by rollcam run); to watch a session before it starts, use rollcam run --serve",
            a.session_dir.display()
        );
    }
    let server = start_page(&a.session_dir, a.addr)?;
    if !a.session_dir.join("session.json").exists() {
        println!("{}: no session.json yet; the page will show the session once it starts", a.session_dir.display());
    }
    println!("live page of {}: {}  (Ctrl-C to stop)", a.session_dir.display(), server.url());
    serve_until_ctrl_c(server);
    Ok(())
}
