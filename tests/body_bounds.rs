//! What a request body may make the service allocate, counted by this
//! binary's own global allocator (its own test binary: the allocator is
//! process-wide).
//!
//! - The duplicate-key walk allocates in proportion to the body, whatever
//!   its shape: a megabyte key over twenty thousand array elements once
//!   cost their product (a path copied per element).
//! - Serving a 16 MiB body of any shape holds at most 8x its size at once
//!   (the body itself included), whether it is refused or parsed: every
//!   sequence is read into its typed vector with a length cap, and no value
//!   tree is built.
//!
//! The tests take turns ([`ONE_AT_A_TIME`]) and send one request at a
//! time, so that the counts are the request's.

use dpmp::fixtures::bodies::repeated;
use dpmp::service::{AppState, RunningServer, ServiceConfig};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicIsize, AtomicUsize, Ordering};
use std::time::Duration;

/// Counts live bytes, their peak, and every byte ever allocated.
struct Counting;

static LIVE: AtomicIsize = AtomicIsize::new(0);
static PEAK: AtomicIsize = AtomicIsize::new(0);
static TOTAL: AtomicUsize = AtomicUsize::new(0);

fn grew(bytes: usize) {
    let live = LIVE.fetch_add(bytes as isize, Ordering::SeqCst) + bytes as isize;
    PEAK.fetch_max(live, Ordering::SeqCst);
    TOTAL.fetch_add(bytes, Ordering::SeqCst);
}

fn shrank(bytes: usize) {
    LIVE.fetch_sub(bytes as isize, Ordering::SeqCst);
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        shrank(layout.size());
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    /// Counted as a new block beside the old one until the old is freed:
    /// the worst case of a moving reallocation.
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            grew(new_size);
            shrank(layout.size());
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Held by each test while it measures: the counters are process-wide.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Peak live bytes above the start, and bytes allocated in all, while `f`
/// runs.
fn measure<T>(f: impl FnOnce() -> T) -> (T, usize, usize) {
    let start = LIVE.load(Ordering::SeqCst);
    PEAK.store(start, Ordering::SeqCst);
    let total = TOTAL.load(Ordering::SeqCst);
    let out = f();
    let peak = (PEAK.load(Ordering::SeqCst) - start).max(0) as usize;
    (out, peak, TOTAL.load(Ordering::SeqCst) - total)
}

const MIB: usize = 1 << 20;

#[test]
fn the_duplicate_key_walk_allocates_in_proportion_to_the_body() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    for (key_bytes, elements) in [(MIB, 20_000), (8 * MIB, 80_000)] {
        let body = format!(
            "{{\"{}\": {}}}",
            "k".repeat(key_bytes),
            repeated("0", 2 * elements)
        );
        let (found, _, total) = measure(|| dpmp::strict_json::find_duplicate_key(body.as_bytes()));
        assert_eq!(found, None);
        assert!(
            total <= 2 * body.len(),
            "{key_bytes} B key over {elements} elements: {total} B allocated for a {} B body",
            body.len()
        );
    }
    // A duplicate under the long key is still found, with its path.
    let body = format!("{{\"{}\": [0, {{\"a\": 1, \"a\": 2}}]}}", "k".repeat(MIB));
    let d = dpmp::strict_json::find_duplicate_key(body.as_bytes()).unwrap();
    assert!(d.path.ends_with("[1].a"));
}

#[test]
fn a_16_mib_body_of_any_shape_holds_at_most_8x_its_size() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let limit = 16 * MIB;
    let config = ServiceConfig::default()
        .with_addr("127.0.0.1:0".parse().unwrap())
        .with_deadline(Duration::from_secs(120));
    let robot = dpmp::robot::Robot::panda().unwrap();
    let server = RunningServer::start(AppState::new(config, robot, None).unwrap()).unwrap();
    let client = reqwest::blocking::Client::builder()
        .timeout(Duration::from_secs(300))
        .build()
        .unwrap();
    // Each body just under the limit (the keys and brackets around the
    // filler take a few dozen bytes).
    let fill = limit - 256;
    let point = "[0.5,0.5,0.5]";
    let sphere = r#"{"id":"s","type":"sphere","center":[0.5,0.5,0.5],"radius":0.01}"#;
    let cases: Vec<(&str, &str, String)> = vec![
        (
            "/v1/optimize",
            "prior mean",
            format!(r#"{{"prior": {{"mean": {}}}}}"#, repeated("0", fill)),
        ),
        (
            "/v1/optimize",
            "covariance rows of one",
            format!(
                r#"{{"prior": {{"mean": [], "cov": {}}}}}"#,
                repeated("[0]", fill)
            ),
        ),
        (
            "/v1/optimize",
            "annotation weights",
            format!(
                r#"{{"prior": {{"annotation": [{{"L": [], "mean_weights": {}}}]}}}}"#,
                repeated("[0]", fill)
            ),
        ),
        (
            "/v1/optimize",
            "cloud points",
            format!(
                r#"{{"obstacles": [{{"id": "c", "type": "points", "radius": 0.01, "points": {}}}]}}"#,
                repeated(point, fill)
            ),
        ),
        (
            "/v1/optimize",
            "many spheres",
            format!(r#"{{"obstacles": {}}}"#, repeated(sphere, fill)),
        ),
        (
            "/v1/optimize",
            "empty via points",
            format!(r#"{{"via_points": {}}}"#, repeated("{}", fill)),
        ),
        (
            "/v1/optimize",
            "start",
            format!(r#"{{"start": {}}}"#, repeated("0", fill)),
        ),
        (
            "/v1/optimize",
            "a long string",
            format!(r#"{{"obstacles": [{{"id": "{}"}}]}}"#, "i".repeat(fill)),
        ),
        (
            "/v1/plan",
            "plan cloud points",
            format!(
                r#"{{"target_box": [0, 0, 1, 1], "obstacles": [{{"id": "c", "type": "points", "radius": 0.01, "points": {}}}]}}"#,
                repeated(point, fill)
            ),
        ),
        (
            "/v1/plan",
            "plan box",
            format!(r#"{{"target_box": {}}}"#, repeated("0", fill)),
        ),
        (
            "/v1/plan",
            "plan image",
            format!(
                r#"{{"target_box": [0, 0, 1, 1], "image_base64": "{}"}}"#,
                "A".repeat(fill)
            ),
        ),
    ];
    for (route, name, body) in cases {
        assert!(body.len() <= limit, "{name}: {} B", body.len());
        let url = server.url(route);
        let (status, peak, _) = measure(|| {
            client
                .post(&url)
                .header("content-type", "application/json")
                .body(body.clone())
                .send()
                .unwrap()
                .status()
                .as_u16()
        });
        // The clone above is the client's own copy of the body: not the
        // server's.
        let server_peak = peak.saturating_sub(body.len());
        let ratio = server_peak as f64 / body.len() as f64;
        eprintln!(
            "{route} {name}: {status}, peak {:.1} MiB = {ratio:.2} x the body",
            server_peak as f64 / MIB as f64
        );
        assert!(status < 500 || status == 503, "{name}: {status}");
        assert!(
            ratio <= 8.0,
            "{route} {name}: peak {server_peak} B = {ratio:.1} x the body"
        );
    }
    server.shutdown().unwrap();
}
