//! Runs of frames: which frames of a video a flag marks, and how a person reads them.

/// The runs of consecutive frames whose flag is set, as `[first, end)`.
pub fn frame_runs(flags: impl IntoIterator<Item = bool>) -> Vec<[usize; 2]> {
    let mut runs: Vec<[usize; 2]> = Vec::new();
    for (f, set) in flags.into_iter().enumerate() {
        if set {
            match runs.last_mut() {
                Some(run) if run[1] == f => run[1] = f + 1,
                _ => runs.push([f, f + 1]),
            }
        }
    }
    runs
}

/// Runs of frames for a person: "frames 0-11 and 60-65 (18 of 66)", "frame 3 (1 of 8)".
pub fn runs_text(runs: &[[usize; 2]], total: usize) -> String {
    let parts: Vec<String> = runs.iter().map(|&[a, b]| if b == a + 1 { format!("{a}") } else { format!("{a}-{}", b - 1) }).collect();
    let count: usize = runs.iter().map(|[a, b]| b - a).sum();
    let list = match parts.len() {
        0 => String::new(),
        1 => parts[0].clone(),
        n => format!("{} and {}", parts[..n - 1].join(", "), parts[n - 1]),
    };
    format!("frame{} {list} ({count} of {total})", if count == 1 { "" } else { "s" })
}
