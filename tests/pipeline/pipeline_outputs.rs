//! `rollcam run --outputs full|video|minimal`: exactly the files each set names in
//! every frame's folder, the session pointing at a video that exists, the set recorded.

use crate::support::pipeline_common;

use pipeline_common::{assert_consistent, counter, fixture, rollcam, session, text};

#[test]
fn each_output_set_writes_exactly_its_files() {
    let tmp = tempfile::tempdir().unwrap();
    let fix = fixture("moving-disc");
    let camera = format!("replay:{}", fix.display());
    let full = ["contact.png", "summary.json", "trace.csv", "trace.png", "trace.svg", "video.gif", "video.npy", "video.tiff"];
    for (set, files, video) in [
        ("full", &full[..], "video.tiff"),
        ("video", &["summary.json", "trace.csv", "video.npy"][..], "video.npy"),
        ("minimal", &["summary.json", "video.npy"][..], "video.npy"),
    ] {
        let out = tmp.path().join(set);
        let o = rollcam(&["run", "--camera", &camera, "--out", out.to_str().unwrap(), "--iters", "5", "--outputs", set], tmp.path());
        assert!(o.status.success(), "{}", text(&o));
        let s = session(&out);
        assert_consistent(&s);
        assert_eq!(counter(&s, "reconstructed"), 2, "{set}");
        assert_eq!(s["config"]["outputs"], set);
        for seq in 0..2 {
            let dir = out.join(format!("rec/frame_{seq:06}"));
            let mut names: Vec<String> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
            names.sort();
            assert_eq!(names, files, "{set}: {}", dir.display());
            let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
            let mut listed: Vec<&str> = summary["files"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
            listed.sort();
            assert_eq!(listed, files, "{set}: summary.json files");
            let v = s["frames"][seq]["video"].as_str().unwrap();
            assert_eq!(v, format!("rec/frame_{seq:06}/{video}"));
            assert!(out.join(v).is_file());
        }
        // The same solve, whatever the files: the videos agree.
        let a = rollcam::io::read_npy(out.join("rec/frame_000001/video.npy")).unwrap();
        let b = rollcam::io::read_npy(tmp.path().join("full/rec/frame_000001/video.npy")).unwrap();
        assert_eq!(a, b, "{set}");
    }
    let o = rollcam(&["run", "--camera", &camera, "--out", tmp.path().join("bad").to_str().unwrap(), "--outputs", "gifs"], tmp.path());
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--outputs"), "{}", text(&o));
}
