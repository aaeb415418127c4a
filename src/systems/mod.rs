//! Systems, one file per phenomenon: the system functions and the CPU kernels they run.

pub mod aging;
pub mod convergence;
pub mod craters;
pub mod diagnostics;
pub mod drift;
pub mod erosion;
pub mod init;
pub mod momentum;
pub mod oceanic_crust;
pub mod relief;
pub mod resample;
pub mod rifting;

/// Logs the wall time of a scope at debug level when dropped.
pub struct DebugTimer {
    name: &'static str,
    start: std::time::Instant,
}

impl DebugTimer {
    /// Starts timing `name`.
    pub fn new(name: &'static str) -> Self {
        Self {
            name,
            start: std::time::Instant::now(),
        }
    }
}

impl Drop for DebugTimer {
    fn drop(&mut self) {
        tracing::debug!(
            ms = self.start.elapsed().as_secs_f64() * 1e3,
            "{}",
            self.name
        );
    }
}
