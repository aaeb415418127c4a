//! The GPU compute backend (wgpu): adapter selection, the [`GpuContext`] resource (device,
//! queue, kernel pipelines, the crust buffers resident on the device) and the
//! [`ComputeBackend`] choice the systems read. One host module per kernel
//! (`shaders/<kernel>.wgsl`), each with its CPU reference `<kernel>_cpu`.
//!
//! What stays on the device, and when it is synced (the crust is also read by CPU systems every
//! step — fronts, collisions, terranes, diagnostics, resampling — so it cannot live only there;
//! docs/gpu.md and docs/gpu-residency.md have the details and the measured bytes):
//! - The whole crust (46 bytes a sample, [`CrustBuffers`]) is kept in device buffers between
//!   steps. It goes up in full only when the host [`Crust`](crate::resources::Crust) changed since the last sync (bevy
//!   change ticks): after a resampling, a load, or a CPU system that wrote the crust undeclared.
//!   A writer that declares the fields it changes ([`write_crust_fields`]) uploads only those.
//! - Kernels do not read back what they write: they mark the fields newer on the device
//!   ([`GpuContext::device_newer`]), and CPU readers pull the fields they need
//!   ([`GpuContext::pull`], [`sync_crust_to_host`], [`pull_or_record`]) without moving the
//!   crust's change tick. The fronts gather their few elevations ([`crust_gather`]) and the
//!   diagnostics reduce on the device ([`crust_reduce`]).
//! - The convergence field (distances to the fronts) goes up once per resampling; per step only
//!   the front-point table (32 bytes a point) and the kernels' uniforms go up.
//! - The resampling's point location ([`resample_locate`]) keeps the reference mesh and its
//!   locator on the device for the whole run and reads the old crust's plates and crust types
//!   from the resident buffers; per resampling it uploads the plate table and reads back one
//!   located source per sample. The sources the host rechecks go back into the kernel's output
//!   on the device ([`sources_patch`]).
//! - The resampling's interpolation ([`resample_interpolate`]) reads the old crust from the
//!   resident buffers and the sources from the location's output, and reads back the new crust
//!   (CPU systems edit it next).
//! - The collision surges after a resampling ([`collision_uplift`]) keep the reference
//!   positions on the device for the run; per surge they upload the distances to the sutured
//!   terrane (found on the CPU by a graph search); the fields they write stay on the device.
//!
//! [`GpuTraffic`] counts the bytes both ways; `planet bench --backend gpu` prints them per step.
//!
//! Layout: [`backend`] (the choice of backend and adapter), [`context`] (device, queue, errors,
//! traffic, and the kernels made on first use), [`residency`] (the resident crust and its
//! sync), [`helpers`] (pipelines, dispatch sizes, bind-group entries), then one host module per
//! kernel. A kernel's host module holds its `#[repr(C)]` types, its pipeline (a [`Kernel`]) and
//! its `<kernel>_dispatch`; its CPU reference `<kernel>_cpu` lives with the system that runs it
//! and takes the same types. Adding a kernel touches no file here but this module list.

pub mod backend;
pub mod context;
pub mod helpers;
pub mod residency;

pub mod aging;
pub mod amplify;
pub mod collision_uplift;
pub mod crust_gather;
pub mod crust_reduce;
pub mod diffusion;
pub mod erosion;
pub mod isostasy;
pub mod resample_interpolate;
pub mod resample_locate;
pub mod sources_patch;
pub mod subduction_uplift;

pub use backend::{
    AdapterSurvey, BackendChoice, ComputeBackend, GpuError, SOFTWARE_ONLY, SelectedBackend,
    select_backend,
};
pub use context::{GpuContext, GpuTraffic, Kernel, run_or_record};
pub use helpers::{COMMON_WGSL, ROW_STRIDE, WORKGROUP_SIZE, shader_source};
pub(crate) use helpers::{compute_pipeline, entry, uniform_buffer};
pub use residency::{
    CrustBuffers, FieldMask, pull_or_record, sync_crust_to_host, sync_crust_to_host_or_record,
    write_crust_fields, write_crust_fields_or_record,
};
