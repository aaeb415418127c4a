//! Input and output: parameters (TOML), map rendering (PNG) and run summaries (JSON).

pub mod maps;
pub mod params;
pub mod summary;
