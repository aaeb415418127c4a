//! Input and output: parameters (TOML), map rendering (PNG), rivers (PNG, GeoJSON), run
//! summaries (JSON), saves, and exports (16-bit heightmaps, GeoTIFF, glTF).

pub mod exemplars;
pub mod export;
pub mod geotiff;
pub mod gltf;
pub mod heightmap;
pub mod hypsometry;
pub mod maps;
pub mod pending;
pub mod rivers;
pub mod save;
pub mod start;
pub mod summary;
pub mod text;
