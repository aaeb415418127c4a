//! Systems, one file per phenomenon: the system functions and the CPU kernels they run.

pub mod aging;
pub mod convergence;
pub mod diagnostics;
pub mod drift;
pub mod erosion;
pub mod init;
pub mod oceanic_crust;
pub mod resample;
