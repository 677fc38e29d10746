//! Writes `examples/import/`: a worked `dpmp data import` example, made by
//! dpmp's own seeded generator so that nothing in it is copied from
//! elsewhere. Three plants (groups) with two target berries each; per
//! target a JPEG image (box already painted), its aligned 16-bit depth PNG,
//! three demonstrations as `joint_states`-style CSV files at 50 Hz, and the
//! plant's obstacles; `manifest.json` ties them together.
//!
//! ```bash
//! cargo run --release --example make_import_example [OUT_DIR]
//! dpmp data import --manifest examples/import/manifest.json --out /tmp/imported
//! ```

use dpmp::promp::{Basis, PrompConfig};
use dpmp::robot::Robot;
use dpmp::synth::generate::Generator;
use dpmp::synth::settings::SynthSettings;
use serde_json::json;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

const PLANTS: usize = 3;
const BERRIES: usize = 2;
const DEMOS: usize = 3;
const RATE_HZ: f64 = 50.0;
const SEED: u64 = 2024;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("examples/import"));
    let robot = Robot::panda()?;
    let mut settings = SynthSettings::new(PLANTS, BERRIES);
    settings.demos.demos = DEMOS;
    let generator = Generator::new(settings, robot.clone())?;
    let basis = Basis::new(&PrompConfig::default())?;
    let mut targets = Vec::new();
    for plant in 0..PLANTS {
        let output = generator.config(SEED, plant)?;
        for (b, record) in output.records.iter().enumerate() {
            let id = format!("plant{plant}-berry{b}");
            let image = format!("images/{id}.jpg");
            write_jpeg(&out.join(&image), &output.images[b])?;
            let depth = format!("depth/{id}.png");
            let depth_image = output.depths[b].as_ref().ok_or("depth is off")?;
            write(&out.join(&depth), &depth_image.encode_png()?)?;
            let demos: Vec<String> = record
                .demos
                .iter()
                .enumerate()
                .map(|(k, demo)| {
                    let file = format!("demos/{id}/{k}.csv");
                    let text = csv(&basis, &robot, &demo.weights, record.duration_s);
                    write(&out.join(&file), text.as_bytes()).map(|()| file)
                })
                .collect::<Result<_, _>>()?;
            targets.push(json!({
                "id": id,
                "group": format!("plant{plant}"),
                "image": image,
                "box": record.bbox,
                "mask_applied": true,
                "depth": depth,
                "demos": demos,
                "obstacles": record.scene.obstacles,
            }));
        }
    }
    let manifest = json!({ "depth_scale_m": 0.001, "targets": targets });
    write(
        &out.join("manifest.json"),
        serde_json::to_string_pretty(&manifest)?.as_bytes(),
    )?;
    println!("wrote {}", out.join("manifest.json").display());
    Ok(())
}

/// A demonstration as a CSV recording: `time` and the joint columns, with
/// an extra `gripper` column a real export might carry.
fn csv(basis: &Basis, robot: &Robot, weights: &[f64], duration_s: f64) -> String {
    let n_basis = basis.n_basis();
    let mut text = String::from("time");
    for name in robot.joint_names() {
        write!(text, ",{name}").ok();
    }
    text.push_str(",gripper\n");
    let samples = (duration_s * RATE_HZ).round() as usize + 1;
    for k in 0..samples {
        let t = k as f64 / RATE_HZ;
        let psi = basis.row_at(t / duration_s);
        write!(text, "{t:.3}").ok();
        for j in 0..robot.dof() {
            let q: f64 = (0..n_basis)
                .map(|i| psi[i] * weights[j * n_basis + i])
                .sum();
            write!(text, ",{q:.6}").ok();
        }
        text.push_str(",0.04\n");
    }
    text
}

fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, bytes)
}

fn write_jpeg(path: &Path, image: &image::RgbImage) -> Result<(), Box<dyn std::error::Error>> {
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 85).encode_image(image)?;
    Ok(write(path, &bytes)?)
}
