//! Shared plotting helpers (plotters): per-joint trajectory bands and simple line charts.
