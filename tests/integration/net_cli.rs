//! `dpmp train` and `dpmp eval` through the real binary on a tiny dataset:
//! exit codes, the JSON on stdout (`mean_final_position_error_m`), the
//! files written, and a clear error for a bad flag.

use crate::common::cli::dpmp;

#[test]
fn train_then_eval_through_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    crate::common::net::write_dataset(&data, 3, 2, 64, 48, 5);
    let (data_s, out) = (data.to_str().unwrap(), dir.path().join("m"));
    let out_s = out.to_str().unwrap();
    let common = [
        "train",
        "--data",
        data_s,
        "--arch",
        "cvae",
        "--latent-tuning",
        "--out",
        out_s,
        "--seed",
        "1",
        "--epochs-tp1",
        "1",
        "--epochs-tp2",
        "1",
        "--epochs-tp3",
        "1",
        "--latent-dim",
        "8",
        "--quiet",
    ];
    let o = dpmp(&common);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["summary"]["epochs"]["tp3"], 1);
    for f in [
        "model.safetensors",
        "config.json",
        "metrics.jsonl",
        "metrics.csv",
        "loss_curves.png",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }

    let eval_dir = dir.path().join("eval");
    let o = dpmp(&[
        "eval",
        "--model",
        out_s,
        "--data",
        data_s,
        "--split",
        "all",
        "--format",
        "json",
        "--out",
        eval_dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let err = report["mean_final_position_error_m"].as_f64().unwrap();
    assert!(err.is_finite() && err >= 0.0);
    assert_eq!(report["targets"], 6);
    for f in ["eval.json", "eval.md", "embedding.png"] {
        assert!(eval_dir.join(f).exists(), "{f}");
    }

    // Without --out the reports go beside the data, never into the model.
    let o = dpmp(&["eval", "--model", out_s, "--data", data_s, "--split", "all"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("config.json")).unwrap()).unwrap();
    let name = config["name"].as_str().unwrap();
    let beside = std::path::Path::new(data_s).join(format!("eval-{name}-all"));
    assert!(beside.join("eval.json").is_file(), "{}", beside.display());
    assert!(
        !out.join("eval-all").exists(),
        "eval wrote into the model folder"
    );

    let o = dpmp(&["eval", "--model", out_s, "--data", data_s, "--split", "dev"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("split"));
    let o = dpmp(&["train", "--data", data_s, "--arch", "gan", "--out", out_s]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("arch"));
}
