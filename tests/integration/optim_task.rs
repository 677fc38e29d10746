//! The request as a prior beside a [`Task`]: the typed prior gives the wire
//! request's answer byte for byte, the wire format is unchanged (field
//! order, unknown fields, JSON paths of errors), and a typed prior is
//! checked as the wire's is.

use dpmp::fixtures::{typical_request, ExampleSettings};
use dpmp::optim::{optimize_prior, optimize_with, OptimizeRequest, PriorSpec, SolveControl, Task};
use dpmp::promp::WeightDistribution;
use dpmp::robot::Robot;
use nalgebra::{DMatrix, DVector};

/// The distribution a full `prior` spec writes.
fn distribution(spec: &PriorSpec, n_basis: usize) -> WeightDistribution {
    let PriorSpec::Full { mean, cov } = spec else {
        panic!("a full prior");
    };
    let n = mean.len();
    WeightDistribution::new(
        DVector::from_column_slice(mean),
        DMatrix::from_fn(n, n, |r, c| cov[r][c]),
        n / n_basis,
        n_basis,
    )
    .unwrap()
}

#[test]
fn a_typed_prior_gives_the_wire_requests_answer_byte_for_byte() {
    let robot = Robot::panda().unwrap();
    let settings = ExampleSettings::default();
    for seed in [0, 7, 21] {
        let request = typical_request(&robot, seed, &settings).unwrap();
        let dist = distribution(&request.prior, request.task.promp.n_basis);
        let basis = request.task.basis().unwrap();
        let ctl = SolveControl::default();
        let wire = optimize_with(&request, &robot, &ctl).unwrap();
        let typed = optimize_prior(&dist, &request.task, &basis, &robot, &ctl).unwrap();
        assert_eq!(
            wire.deterministic_json(),
            typed.deterministic_json(),
            "seed {seed}"
        );
    }
}

#[test]
fn a_request_writes_the_prior_first_and_round_trips() {
    let robot = Robot::panda().unwrap();
    let request = typical_request(&robot, 3, &ExampleSettings::default()).unwrap();
    let text = serde_json::to_string(&request).unwrap();
    assert!(text.starts_with("{\"prior\":"), "{}", &text[..40]);
    let again: OptimizeRequest = serde_json::from_str(&text).unwrap();
    assert_eq!(serde_json::to_string(&again).unwrap(), text);
    // The task alone is the same object without its prior.
    let mut value = serde_json::to_value(&request).unwrap();
    value.as_object_mut().unwrap().remove("prior");
    assert_eq!(value, serde_json::to_value(&request.task).unwrap());
}

/// The JSON path serde_path_to_error reports for `text` parsed as `T`.
fn error_path<T: serde::de::DeserializeOwned + std::fmt::Debug>(text: &str) -> (String, String) {
    let mut de = serde_json::Deserializer::from_str(text);
    let e = serde_path_to_error::deserialize::<_, T>(&mut de).unwrap_err();
    (e.path().to_string(), e.inner().to_string())
}

#[test]
fn task_field_errors_keep_their_json_path_in_the_request_and_alone() {
    let prior = r#""prior": {"mean": [0.0], "cov": [[1.0]]}"#;
    let cases = [
        (r#""options": {"lambda": "x"}"#, "options.lambda"),
        (r#""goal": {"position": [0, 0]}"#, "goal.position"),
        (
            r#""obstacles": [{"id": "a", "type": "sphere", "center": [0,0,0], "radius": "r"}]"#,
            "obstacles[0]",
        ),
        (r#""duration_s": true"#, "duration_s"),
    ];
    for (field, path) in cases {
        let (got, message) = error_path::<OptimizeRequest>(&format!("{{{prior}, {field}}}"));
        assert!(got.starts_with(path), "request {field}: {got} ({message})");
        let (got, message) = error_path::<Task>(&format!("{{{field}}}"));
        assert!(got.starts_with(path), "task {field}: {got} ({message})");
    }
    let (got, _) = error_path::<OptimizeRequest>(r#"{"prior": {"mean": "m"}}"#);
    assert!(got.starts_with("prior"), "{got}");
}

#[test]
fn unknown_fields_are_refused_and_a_task_has_no_prior() {
    let (_, message) = error_path::<OptimizeRequest>(
        r#"{"prior": {"mean": [0.0], "cov": [[1.0]]}, "clearence_m": 0.02}"#,
    );
    assert!(message.contains("unknown field `clearence_m`"), "{message}");
    let (_, message) = error_path::<Task>(r#"{"prior": {"mean": [0.0], "cov": [[1.0]]}}"#);
    assert!(message.contains("unknown field `prior`"), "{message}");
    let empty: Task = serde_json::from_str("{}").unwrap();
    assert_eq!(
        serde_json::to_value(&empty).unwrap(),
        serde_json::to_value(Task::default()).unwrap()
    );
}

#[test]
fn a_typed_prior_is_checked_as_the_wire_prior_is() {
    let robot = Robot::panda().unwrap();
    let request = typical_request(&robot, 1, &ExampleSettings::default()).unwrap();
    let basis = request.task.basis().unwrap();
    let dist = distribution(&request.prior, 8);
    // Too few basis functions for the task's promp.
    let short = WeightDistribution::new(
        dist.mean.rows(0, 49).into(),
        dist.cov.view((0, 0), (49, 49)).into(),
        7,
        7,
    )
    .unwrap();
    let e = request.task.validate(&robot, &short, &basis).unwrap_err();
    assert!(e.to_string().contains("prior.mean"), "{e}");
    // A non-finite covariance entry is named by its row and column.
    let mut broken = dist.clone();
    broken.cov[(3, 5)] = f64::NAN;
    let e = request.task.validate(&robot, &broken, &basis).unwrap_err();
    assert!(e.to_string().contains("prior.cov[3][5]"), "{e}");
    // An indefinite covariance is repaired with the wire path's warning.
    let mut indefinite = dist.clone();
    indefinite.cov[(0, 0)] = -1.0;
    let typed = request.task.validate(&robot, &indefinite, &basis).unwrap();
    let wire = OptimizeRequest {
        prior: PriorSpec::from(&indefinite),
        task: request.task.clone(),
    }
    .validate(&robot)
    .unwrap();
    assert_eq!(typed.warnings(), wire.warnings());
    assert!(typed.warnings()[0].contains("not positive semi-definite"));
    assert_eq!(typed.prior().cov, wire.prior().cov);
}
