//! `dpmp prior` end to end: example -> inspect (json, table) -> plot, and
//! bad input exits non-zero naming the file and field.

use std::process::Command;

fn dpmp() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dpmp"))
}

#[test]
fn example_inspect_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let ann = dir.path().join("ann");
    let out = dpmp()
        .args(["prior", "example", "--out"])
        .arg(&ann)
        .args(["--index", "4", "--seed", "2"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let out = dpmp()
        .args(["prior", "inspect", "--annotation"])
        .arg(&ann)
        .args(["--index", "4"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mean = v["mean"].as_array().unwrap();
    let std = v["std"].as_array().unwrap();
    assert_eq!(mean.len(), 150);
    assert_eq!(mean[0].as_array().unwrap().len(), 7);
    assert_eq!(std.len(), 150);
    // Starts at the paper's home configuration, joint 6 ends near 3.24 rad.
    assert!((mean[0][3].as_f64().unwrap() + 2.5334).abs() < 0.02);
    assert!((mean[149][5].as_f64().unwrap() - 3.239).abs() < 0.3);
    assert_eq!(v["repaired"], false);
    assert!(v["min_eigenvalue"].as_f64().unwrap() > -1e-9);

    let out = dpmp()
        .args(["prior", "inspect", "--format", "table", "--annotation"])
        .arg(&ann)
        .args(["--index", "4"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("J7") && text.contains("repaired: no"),
        "{text}"
    );

    let png = dir.path().join("prior.png");
    let out = dpmp()
        .args(["prior", "plot", "--annotation"])
        .arg(&ann)
        .args(["--index", "4", "--out"])
        .arg(&png)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (1400, 900));
    let svg = dir.path().join("prior.svg");
    let out = dpmp()
        .args(["prior", "plot", "--annotation"])
        .arg(&ann)
        .args(["--index", "4", "--out"])
        .arg(&svg)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
}

#[test]
fn bad_input_names_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let ann = dir.path().join("ann");
    assert!(dpmp()
        .args(["prior", "example", "--out"])
        .arg(&ann)
        .output()
        .unwrap()
        .status
        .success());
    std::fs::write(
        ann.join("J2/0.json"),
        r#"{"mean_weights": [1,2,3], "L": []}"#,
    )
    .unwrap();
    let out = dpmp()
        .args(["prior", "inspect", "--annotation"])
        .arg(&ann)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("J2/0.json") && err.contains("mean_weights"),
        "{err}"
    );

    std::fs::write(ann.join("J2/0.json"), "not json").unwrap();
    let out = dpmp()
        .args(["prior", "inspect", "--annotation"])
        .arg(&ann)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("J2/0.json"));

    let out = dpmp()
        .args(["prior", "inspect", "--width", "nan", "--annotation"])
        .arg(&ann)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--width"));

    let out = dpmp()
        .args(["prior", "plot", "--annotation"])
        .arg(&ann)
        .args(["--out", "x.gif"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(!std::path::Path::new("x.gif").exists());
}
