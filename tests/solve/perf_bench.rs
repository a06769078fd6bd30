//! The benchmark's own pieces: preset geometry, medians, the Markdown splice, timing
//! wrappers that count what they wrap.

use rollcam::model::op::{pseudo_random, Dense, Operator};
use rollcam::perf::bench::{median, preset, splice_markdown, time_iterations, TimedOp, MD_BEGIN, MD_END, PRESETS};
use rollcam::solve::prox::TotalVariation;
use std::sync::atomic::Ordering;

#[test]
fn presets_have_the_stated_frame_count() {
    // K = M/2 + N_l - 1 from the exact shutter weights, for every preset.
    for p in PRESETS {
        let k = p.timing().weights().unwrap().frames();
        assert_eq!(k, p.frames(), "{}", p.name);
    }
    assert_eq!(preset("paper-8x").unwrap().frames(), 137);
    assert!(preset("nope").is_none());
}

#[test]
fn median_of_odd_and_even_lists() {
    assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
    assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
    assert!(median(&[]).is_nan());
}

#[test]
fn markdown_splice_replaces_only_the_generated_block() {
    let doc = format!("# T\nintro\n{MD_BEGIN}\nold table\n{MD_END}\nafter\n");
    let out = splice_markdown(&doc, "new table\n");
    assert!(out.contains("new table") && !out.contains("old table"));
    assert!(out.starts_with("# T\nintro\n") && out.ends_with("after\n"));
    // Splicing again keeps one block.
    let again = splice_markdown(&out, "newer\n");
    assert_eq!(again.matches(MD_BEGIN).count(), 1);
    assert!(again.contains("newer") && !again.contains("new table"));
    // Without markers, a block is appended.
    let fresh = splice_markdown("# P\n", "x\n");
    assert!(fresh.starts_with("# P\n") && fresh.contains(MD_BEGIN) && fresh.contains(MD_END));
}

#[test]
fn timing_wrapper_passes_results_through_and_counts_time() {
    let a = Dense { rows: 5, cols: 8, a: pseudo_random(40, 1) };
    let t = TimedOp::new(&a);
    let x = pseudo_random(8, 2);
    let (mut y1, mut y2) = (vec![0.0; 5], vec![0.0; 5]);
    a.forward(&x, &mut y1);
    t.forward(&x, &mut y2);
    assert_eq!(y1, y2);
    assert!(t.forward_ns.load(Ordering::Relaxed) > 0);
    assert_eq!(t.adjoint_ns.load(Ordering::Relaxed), 0);
}

#[test]
fn iteration_timing_reports_the_timed_iterations() {
    let a = Dense { rows: 6, cols: 12, a: pseudo_random(72, 3) };
    let b = pseudo_random(6, 4);
    let tv = TotalVariation::new((1, 3, 4), 0.01, 1.0);
    let r = time_iterations(&a, &rollcam::model::data::DataTerm::new(&b), &tv, 50.0, 2, 5);
    assert_eq!(r.iterations, 5);
    assert!(r.s_per_iter > 0.0 && r.min_s <= r.s_per_iter && r.s_per_iter <= r.max_s);
    assert!(r.forward_s > 0.0 && r.adjoint_s > 0.0 && r.tv_prox_s > 0.0);
}

#[test]
fn the_psnr_block_is_spliced_apart_from_the_preset_table() {
    use rollcam::perf::bench::{splice_psnr_markdown, PSNR_MD_BEGIN, PSNR_MD_END};
    let doc = format!("# T\n{MD_BEGIN}\ntable\n{MD_END}\nmid\n{PSNR_MD_BEGIN}\nold psnr\n{PSNR_MD_END}\nend\n");
    let out = splice_psnr_markdown(&doc, "new psnr\n");
    assert!(out.contains("table") && out.contains("new psnr") && !out.contains("old psnr"));
    assert!(out.ends_with("end\n") && out.contains("mid\n"));
    let out2 = splice_markdown(&out, "table 2\n");
    assert!(out2.contains("table 2") && out2.contains("new psnr") && !out2.contains("\ntable\n"));
}

#[test]
fn per_frame_psnr_uses_the_whole_videos_peak() {
    use rollcam::perf::bench::frame_psnr_db;
    // Two frames of 4 pixels; the truth's peak (2) is in frame 0; frame 1 is dark.
    let truth = [2.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let x = [2.0f32, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0];
    let db = frame_psnr_db(&x, &truth, 2);
    assert!(db[0].is_infinite());
    // MSE of frame 1 = 0.04 / 4 = 0.01; PSNR = 10 log10(4 / 0.01) = 26.02 dB.
    assert!((db[1] - 26.0206).abs() < 1e-3, "{}", db[1]);
}

#[test]
fn time_to_psnr_on_the_small_preset_reaches_its_milestones_in_order() {
    use rollcam::perf::bench::time_to_psnr;
    let p = preset("small").unwrap();
    let settings =
        rollcam::solve::problem::SolveSettings { tau: rollcam::solve::tau::Tau::Relative(2e-4), alpha: 1.0, ..Default::default() }.validate().unwrap();
    let r = time_to_psnr(&p, 22.0, 3000, &settings);
    assert_eq!(r.milestones.iter().map(|m| m.db).collect::<Vec<_>>(), vec![20.0, 22.0]);
    let its: Vec<usize> = r.milestones.iter().map(|m| m.iterations.expect("milestone reached")).collect();
    assert!(its[0] <= its[1], "{its:?}");
    assert_eq!(r.iterations, Some(its[1]));
    // The run stops at the target: the last iterate is the one that reached it.
    assert!(r.final_db >= 22.0 && r.best_db >= r.final_db - 1e-9);
    assert_eq!(r.frames, p.frames());
    assert!(r.frame_db_min <= r.frame_db_median && r.frames_below_target <= r.frames);
    assert!(r.worst_frame < r.frames);
}
