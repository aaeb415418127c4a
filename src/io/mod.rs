//! Input and output: parameters (TOML), map rendering (PNG), run summaries (JSON) and saves.

pub mod maps;
pub mod params;
pub mod plugin_params;
pub mod save;
pub mod summary;
