//! Training and evaluation of the dPMP network: losses (reconstruction,
//! KL, the paper's Eq. 7 and Eq. 8 in candle ops), Adam, the dataset in
//! batches, the three training phases (tp1, tp2, tp3) and the Direct
//! baseline, the training driver with logging, checkpoints and resume, and
//! the paper's evaluation tables (I, II, III).

pub mod adam;
pub mod baseline;
pub mod data;
pub mod embedding;
pub mod eval;
pub mod final_point;
pub mod log;
pub mod losses;
pub mod norm;
pub mod phases;
pub mod plan_eval;
pub mod settings;
pub mod tcp_loss;
pub mod trainer;

pub use settings::{ShapeSettings, TrainSettings};
pub use trainer::{train, train_for, TrainOutcome};
