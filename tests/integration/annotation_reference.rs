//! The published annotations (../shared/reference/dpmp-annotation), when
//! present: all 25 decode, K = 4 is indefinite and gets repaired with a
//! warning, and the facts in REFERENCE.md hold. Skips cleanly when the
//! reference folder is absent (a user clones only the project).

use dpmp::promp::{annotation, Basis, PrompConfig};
use std::path::PathBuf;

fn reference_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/reference/dpmp-annotation");
    dir.is_dir().then_some(dir)
}

#[test]
fn published_annotations_decode_and_repair() {
    let Some(dir) = reference_dir() else {
        eprintln!("skipped: ../shared/reference/dpmp-annotation not present");
        return;
    };
    let basis = Basis::new(&PrompConfig::default()).unwrap();
    let home = [0.0348, -1.0102, -0.1525, -2.5334, -0.1583, 2.8798, 0.0543];
    let mut repaired = Vec::new();
    for k in 0..25 {
        let prior = annotation::load_dir(&dir, k).unwrap();
        assert_eq!(prior.distribution.dim(), 56);
        if prior.repaired {
            repaired.push(k);
            assert!(!prior.warnings.is_empty());
        }
        let mean = prior.distribution.trajectory_mean(&basis);
        for j in 0..7 {
            assert!((mean[(0, j)] - home[j]).abs() < 0.05, "K={k} joint {j}");
        }
        // Joint 6 never ends past its 3.7525 rad limit.
        assert!(mean[(149, 5)] < 3.7525);
    }
    assert!(
        repaired.contains(&4),
        "K = 4 is indefinite and must be repaired: {repaired:?}"
    );
    let k4 = annotation::load_dir(&dir, 4).unwrap();
    assert!(k4.min_eigenvalue < -1.0, "{}", k4.min_eigenvalue);
}
