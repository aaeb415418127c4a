//! Contributed phenomena: plugins written with nothing but the public [`prelude`](crate::prelude),
//! as a third party would write them, yet linked into the `planet` binary and listed by
//! `planet plugins`. The plugin author's guide (`docs/plugins.md`, below) uses them as its worked
//! example; its code blocks are compiled and run as doc-tests.

pub mod hotspots;

pub use hotspots::{Edifice, Hotspot, HotspotPlugin, HotspotSettings, HotspotState};

#[doc = include_str!("../../docs/plugins.md")]
pub mod guide {}
