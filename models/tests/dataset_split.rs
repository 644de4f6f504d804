//! `supine-models dataset` refuses a split that leaves the train or the test part empty, before rendering
//! anything (issue 11, item 8).

use std::process::Command;

#[test]
fn a_split_with_an_empty_part_is_refused_before_any_work() {
    let out_dir = std::env::temp_dir().join(format!("supine-dataset-split-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out_dir);
    for (bodies, fraction, want) in [
        ("1", "0.7", "gives 1 training and 0 test bodies"),
        ("5", "0.05", "gives 0 training and 5 test bodies"),
        ("4", "1", "gives 4 training and 0 test bodies"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_supine-models"))
            .args([
                "dataset",
                "--views",
                "1",
                "--previews",
                "0",
                "--bodies",
                bodies,
                "--train-fraction",
                fraction,
            ])
            .arg("--out")
            .arg(&out_dir)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            out.status.code(),
            Some(2),
            "--bodies {bodies} --train-fraction {fraction}: {err}"
        );
        assert!(err.contains(want), "{err}");
        assert!(!out_dir.exists(), "nothing is written");
    }
}
