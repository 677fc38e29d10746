//! `dpmp prior` end to end: example -> inspect (json, table) -> plot, and
//! bad input exits non-zero naming the file and field.

use crate::common::cli::{arg, dpmp, dpmp_ok, stderr};

#[test]
fn example_inspect_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let ann = dir.path().join("ann");
    let ann = arg(&ann);
    dpmp_ok(&[
        "prior", "example", "--out", ann, "--index", "4", "--seed", "2",
    ]);

    let out = dpmp_ok(&["prior", "inspect", "--annotation", ann, "--index", "4"]);
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

    let out = dpmp_ok(&[
        "prior",
        "inspect",
        "--format",
        "table",
        "--annotation",
        ann,
        "--index",
        "4",
    ]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("J7") && text.contains("repaired: no"),
        "{text}"
    );

    let png = dir.path().join("prior.png");
    let plot = |out: &str| {
        dpmp_ok(&[
            "prior",
            "plot",
            "--annotation",
            ann,
            "--index",
            "4",
            "--out",
            out,
        ])
    };
    plot(arg(&png));
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (1400, 900));
    let svg = dir.path().join("prior.svg");
    plot(arg(&svg));
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
}

#[test]
fn bad_input_names_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let ann = dir.path().join("ann");
    dpmp_ok(&["prior", "example", "--out", arg(&ann)]);
    let inspect = || dpmp(&["prior", "inspect", "--annotation", arg(&ann)]);

    std::fs::write(
        ann.join("J2/0.json"),
        r#"{"mean_weights": [1,2,3], "L": []}"#,
    )
    .unwrap();
    let out = inspect();
    assert!(!out.status.success());
    let err = stderr(&out);
    assert!(
        err.contains("J2/0.json") && err.contains("mean_weights"),
        "{err}"
    );

    std::fs::write(ann.join("J2/0.json"), "not json").unwrap();
    let out = inspect();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("J2/0.json"));

    let out = dpmp(&[
        "prior",
        "inspect",
        "--width",
        "nan",
        "--annotation",
        arg(&ann),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--width"));

    let out = dpmp(&["prior", "plot", "--annotation", arg(&ann), "--out", "x.gif"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(!std::path::Path::new("x.gif").exists());
}
