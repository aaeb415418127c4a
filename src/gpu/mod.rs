//! The GPU compute backend (wgpu): adapter selection, the [`GpuContext`] resource (device,
//! queue, kernel pipelines, the crust buffers resident on the device) and the
//! [`ComputeBackend`] choice the systems read. One host module per kernel
//! (`shaders/<kernel>.wgsl`), each with its CPU reference `<kernel>_cpu`.
//!
//! What stays on the device, and when it is synced (the crust is also read by CPU systems every
//! step — fronts, collisions, terranes, diagnostics, resampling — so it cannot live only there;
//! docs/gpu.md and docs/gpu-residency.md have the details and the measured bytes):
//! - The whole crust (46 bytes a sample, [`CrustBuffers`]) is kept in device buffers between
//!   steps. It goes up in full only when the host [`Crust`] changed since the last sync (bevy
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

pub mod aging;
pub mod amplify;
pub mod collision_uplift;
pub mod crust_gather;
pub mod crust_reduce;
pub mod erosion;
pub mod resample_interpolate;
pub mod resample_locate;
pub mod sources_patch;
pub mod subduction_uplift;

use std::sync::{Arc, Mutex};

use bevy_ecs::change_detection::{DetectChangesMut, Tick};
use bevy_ecs::prelude::*;

use crate::resources::Crust;

/// Threads per workgroup of every per-sample kernel (`WORKGROUP_SIZE` in
/// `shaders/common/bytes.wgsl`).
pub const WORKGROUP_SIZE: u32 = 256;

/// Shared WGSL prepended to every kernel (the files of `shaders/common/`, in name order).
pub const COMMON_WGSL: &str = include_str!("../../shaders/common/bytes.wgsl");

/// The full source of a kernel: [`COMMON_WGSL`] followed by the kernel's own file.
pub fn shader_source(kernel_wgsl: &str) -> String {
    format!("{COMMON_WGSL}\n{kernel_wgsl}")
}

/// How the note of [`select_backend`] starts when `auto` found only a software adapter.
pub const SOFTWARE_ONLY: &str = "no hardware GPU";

/// Which compute backend the user asked for (`--backend`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BackendChoice {
    /// A hardware GPU when there is one, the CPU otherwise (software adapters are not used).
    #[default]
    Auto,
    /// Any wgpu adapter, a software one (Mesa's lavapipe) included; an error without one.
    Gpu,
    /// The CPU (rayon) kernels.
    Cpu,
}

impl std::str::FromStr for BackendChoice {
    type Err = GpuError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Self::Auto),
            "gpu" => Ok(Self::Gpu),
            "cpu" => Ok(Self::Cpu),
            other => Err(GpuError::UnknownBackend(other.to_string())),
        }
    }
}

/// The backend the per-sample kernels run on (a resource; the CPU unless a [`GpuContext`] was
/// installed with [`crate::Simulation::set_backend`]).
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ComputeBackend {
    /// rayon kernels on the host.
    #[default]
    Cpu,
    /// wgpu compute kernels; the [`GpuContext`] resource is present.
    Gpu,
}

/// What went wrong with the GPU backend.
#[derive(Debug, Clone, thiserror::Error)]
pub enum GpuError {
    /// `--backend` was given an unknown name.
    #[error("unknown compute backend `{0}`: expected auto, gpu or cpu")]
    UnknownBackend(String),
    /// No wgpu adapter at all.
    #[error(
        "no GPU adapter found (wgpu sees none{0}); on Linux without a GPU install Mesa's \
         lavapipe (apt-get install mesa-vulkan-drivers libvulkan1), or use --backend cpu"
    )]
    NoAdapter(String),
    /// The adapter would not open a device.
    #[error("could not open the GPU device on {adapter}: {message}")]
    Device {
        /// Adapter name.
        adapter: String,
        /// wgpu's message.
        message: String,
    },
    /// A buffer, pipeline or dispatch failed (validation error, lost device, failed mapping).
    #[error("GPU kernel `{kernel}` failed: {message}")]
    Kernel {
        /// The kernel (or buffer operation).
        kernel: &'static str,
        /// What failed.
        message: String,
    },
    /// A problem too large for one dispatch.
    #[error("{0}")]
    TooLarge(String),
    /// A CPU system wrote the host crust while the device held newer fields (it did not pull
    /// them first with [`sync_crust_to_host`] or [`GpuContext::pull`]); uploading the host copy
    /// would silently lose the device's newer data.
    #[error(
        "the host crust was written while the device held newer fields ({0:?}); \
         pull them first (gpu::sync_crust_to_host) before writing the crust"
    )]
    StaleHostWrite(FieldMask),
}

/// A set of the resident crust fields (bits), used to record which ones the device holds newer
/// than the host [`Crust`] (the first five bits, [`FieldMask::ALL`]) and which ones a host
/// writer declares ([`write_crust_fields`], any bit).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FieldMask(pub u16);

impl FieldMask {
    /// No field.
    pub const NONE: Self = Self(0);
    /// Elevation.
    pub const ELEVATION: Self = Self(1);
    /// Crust age.
    pub const AGE: Self = Self(2);
    /// Orogeny.
    pub const OROGENY: Self = Self(4);
    /// Orogeny age.
    pub const OROGENY_AGE: Self = Self(8);
    /// Fold direction.
    pub const FOLD_DIR: Self = Self(16);
    /// Every field a kernel writes (crust type is never written on the device).
    pub const ALL: Self = Self(31);
    /// Crust thickness (no kernel writes it).
    pub const THICKNESS: Self = Self(32);
    /// Ridge direction (no kernel writes it).
    pub const RIDGE_DIR: Self = Self(64);
    /// Plate id (no kernel writes it).
    pub const PLATE: Self = Self(128);
    /// Crust type (no kernel writes it).
    pub const CRUST_TYPE: Self = Self(256);
    /// Every resident field.
    pub const EVERY_FIELD: Self = Self(511);
    /// True when no bit is set.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// True when every bit of `other` is set.
    pub fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    /// The bits set in both.
    pub fn and(self, other: Self) -> Self {
        Self(self.0 & other.0)
    }
}

impl std::ops::BitOr for FieldMask {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

impl std::ops::BitOrAssign for FieldMask {
    fn bitor_assign(&mut self, rhs: Self) {
        self.0 |= rhs.0;
    }
}

/// Bytes that crossed the bus, both ways, since the context was made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuTraffic {
    /// Host to device, bytes.
    pub uploaded_bytes: u64,
    /// Device to host, bytes.
    pub downloaded_bytes: u64,
    /// Kernel dispatches.
    pub dispatches: u64,
    /// Full uploads of the resident crust.
    pub crust_uploads: u64,
    /// Resamplings whose point location ran on the device.
    pub locations: u64,
    /// Samples of those locations that the kernel left to the CPU (near an edge or a tie).
    pub rechecked_samples: u64,
    /// Collision surges applied on the device.
    pub collision_surges: u64,
    /// Resamplings whose interpolation ran on the device.
    pub interpolations: u64,
}

/// The crust fields resident on the device (see the module documentation).
pub struct CrustBuffers {
    /// Samples.
    pub len: usize,
    /// Elevation, f32 per sample, km.
    pub elevation_km: wgpu::Buffer,
    /// Crust type, u8 per sample packed four to a word.
    pub crust_type: wgpu::Buffer,
    /// Crust age, f32 per sample, My.
    pub age_my: wgpu::Buffer,
    /// Orogeny, u8 per sample packed four to a word.
    pub orogeny: wgpu::Buffer,
    /// Orogeny age, f32 per sample, My.
    pub orogeny_age_my: wgpu::Buffer,
    /// Fold direction, three f32 per sample, plate frame.
    pub fold_dir: wgpu::Buffer,
    /// Crust thickness, f32 per sample, km (no kernel writes it; the resampling reads it).
    pub thickness_km: wgpu::Buffer,
    /// Ridge direction, three f32 per sample, plate frame (no kernel writes it; the
    /// resampling reads it).
    pub ridge_dir: wgpu::Buffer,
    /// Plate id, u32 per sample (no kernel writes it; the resampling reads it).
    pub plate: wgpu::Buffer,
}

/// The wgpu device and everything the kernels keep on it (a resource, present only on the GPU
/// backend).
#[derive(Resource)]
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter it came from.
    pub adapter: wgpu::AdapterInfo,
    errors: Arc<Mutex<Vec<String>>>,
    pub(crate) erosion: erosion::ErosionKernel,
    pub(crate) aging: aging::AgingKernel,
    pub(crate) uplift: subduction_uplift::UpliftKernel,
    pub(crate) locate: resample_locate::LocateKernel,
    pub(crate) collision: collision_uplift::CollisionKernel,
    pub(crate) interpolate: resample_interpolate::InterpolateKernel,
    pub(crate) gather: crust_gather::GatherKernel,
    pub(crate) reduce: crust_reduce::ReduceKernel,
    pub(crate) patch: sources_patch::PatchKernel,
    crust: Option<CrustBuffers>,
    crust_synced: Option<Tick>,
    device_newer: FieldMask,
    staging: Option<wgpu::Buffer>,
    orogeny_scratch: Vec<u8>,
    /// Pull every field a kernel wrote right after the kernel (the behaviour before lazy host
    /// sync; used by tests to check that lazy sync changes no result). Off by default.
    pub eager_sync: bool,
    /// Bytes moved and dispatches made.
    pub traffic: GpuTraffic,
    /// The first failure of a kernel run by a system; the simulation stops with it.
    pub failure: Option<GpuError>,
}

/// The outcome of [`select_backend`].
pub struct SelectedBackend {
    /// The backend to use.
    pub backend: ComputeBackend,
    /// The context, for the GPU backend.
    pub context: Option<GpuContext>,
    /// A line for the user: which adapter, or why the CPU.
    pub note: String,
}

/// Blocks on a future (wgpu's adapter and device requests complete at once on native backends).
fn block_on<F: std::future::Future>(f: F) -> F::Output {
    pollster::block_on(f)
}

fn type_rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// Picks the backend for `choice`: `Cpu` always gives the CPU; `Gpu` the best adapter wgpu finds
/// (hardware first, then software such as lavapipe) or an error; `Auto` a hardware adapter, or
/// the CPU with a note saying why. The `WGPU_BACKEND` environment variable limits the wgpu
/// backends searched, as in wgpu.
pub fn select_backend(choice: BackendChoice) -> Result<SelectedBackend, GpuError> {
    if choice == BackendChoice::Cpu {
        return Ok(SelectedBackend {
            backend: ComputeBackend::Cpu,
            context: None,
            note: "compute backend: cpu".into(),
        });
    }
    let desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    let backends = desc.backends;
    let instance = wgpu::Instance::new(desc);
    let mut adapters = block_on(instance.enumerate_adapters(backends));
    adapters.sort_by_key(|a| type_rank(a.get_info().device_type));
    let hardware = adapters
        .iter()
        .position(|a| a.get_info().device_type != wgpu::DeviceType::Cpu);
    let pick = match choice {
        BackendChoice::Auto => hardware,
        _ => (!adapters.is_empty()).then_some(0),
    };
    let Some(k) = pick else {
        if choice == BackendChoice::Auto {
            let why = match adapters.first() {
                Some(a) => format!(
                    "{SOFTWARE_ONLY} (only the software adapter {}); compute backend: cpu",
                    a.get_info().name
                ),
                None => format!(
                    "{}; compute backend: cpu",
                    GpuError::NoAdapter(format!(" for backends {backends:?}"))
                ),
            };
            return Ok(SelectedBackend {
                backend: ComputeBackend::Cpu,
                context: None,
                note: why,
            });
        }
        return Err(GpuError::NoAdapter(format!(" for backends {backends:?}")));
    };
    let adapter = adapters.swap_remove(k);
    let context = GpuContext::new(&adapter)?;
    let info = &context.adapter;
    let note = format!(
        "compute backend: gpu ({}, {:?}, {:?})",
        info.name, info.device_type, info.backend
    );
    Ok(SelectedBackend {
        backend: ComputeBackend::Gpu,
        context: Some(context),
        note,
    })
}

impl GpuContext {
    /// Opens a device on `adapter` and builds every kernel's pipeline.
    pub fn new(adapter: &wgpu::Adapter) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        // Everything the adapter offers (the large storage bindings matter at 4M samples).
        let limits = adapter.limits();
        let (device, queue) = block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("tectonic compute device"),
            required_features: wgpu::Features::empty(),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: info.name.clone(),
            message: e.to_string(),
        })?;
        let errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.lock() {
                v.push(e.to_string());
            }
        }));
        let erosion = erosion::ErosionKernel::new(&device);
        let aging = aging::AgingKernel::new(&device);
        let uplift = subduction_uplift::UpliftKernel::new(&device);
        let locate = resample_locate::LocateKernel::new(&device);
        let collision = collision_uplift::CollisionKernel::new(&device);
        let interpolate = resample_interpolate::InterpolateKernel::new(&device);
        let gather = crust_gather::GatherKernel::new(&device);
        let reduce = crust_reduce::ReduceKernel::new(&device);
        let patch = sources_patch::PatchKernel::new(&device);
        let ctx = Self {
            device,
            queue,
            adapter: info,
            errors,
            erosion,
            aging,
            uplift,
            locate,
            collision,
            interpolate,
            gather,
            reduce,
            patch,
            crust: None,
            crust_synced: None,
            device_newer: FieldMask::NONE,
            staging: None,
            orogeny_scratch: Vec::new(),
            eager_sync: false,
            traffic: GpuTraffic::default(),
            failure: None,
        };
        ctx.check("pipelines")?;
        Ok(ctx)
    }

    /// The first wgpu error recorded since the last check, as a [`GpuError`] naming `kernel`.
    pub(crate) fn check(&self, kernel: &'static str) -> Result<(), GpuError> {
        let mut v = self.errors.lock().map_err(|_| GpuError::Kernel {
            kernel,
            message: "error log poisoned".into(),
        })?;
        if let Some(first) = v.first().cloned() {
            v.clear();
            return Err(GpuError::Kernel {
                kernel,
                message: first,
            });
        }
        Ok(())
    }

    /// A storage buffer of `bytes` bytes (rounded up to 4), usable as copy source and target.
    pub fn storage_buffer(&self, label: &str, bytes: usize) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (bytes.max(4).div_ceil(4) * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }

    /// Writes `data` at the start of `buffer` (padded with zeros to a multiple of 4 bytes).
    pub fn upload(&mut self, buffer: &wgpu::Buffer, data: &[u8]) {
        if data.is_empty() {
            return;
        }
        if data.len().is_multiple_of(4) {
            self.queue.write_buffer(buffer, 0, data);
        } else {
            let mut padded = data.to_vec();
            padded.resize(data.len().div_ceil(4) * 4, 0);
            self.queue.write_buffer(buffer, 0, &padded);
        }
        self.traffic.uploaded_bytes += data.len() as u64;
    }

    /// Copies the first `out.len()` bytes of `buffer` into `out` (waits for the device).
    pub fn download(
        &mut self,
        kernel: &'static str,
        buffer: &wgpu::Buffer,
        out: &mut [u8],
    ) -> Result<(), GpuError> {
        if out.is_empty() {
            return Ok(());
        }
        let size = (out.len().div_ceil(4) * 4) as u64;
        if self.staging.as_ref().is_none_or(|s| s.size() < size) {
            self.staging = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback staging"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let Some(staging) = self.staging.as_ref() else {
            return Err(GpuError::Kernel {
                kernel,
                message: "no staging buffer".into(),
            });
        };
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        enc.copy_buffer_to_buffer(buffer, 0, staging, 0, size);
        self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, 0..size, move |r| {
            let _ = tx.send(r);
        });
        let fail = |message: String| GpuError::Kernel { kernel, message };
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| fail(e.to_string()))?;
        match rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(fail(e.to_string())),
            Err(e) => return Err(fail(e.to_string())),
        }
        {
            let view = staging
                .get_mapped_range(0..size)
                .map_err(|e| fail(e.to_string()))?;
            out.copy_from_slice(&view[..out.len()]);
        }
        staging.unmap();
        self.traffic.downloaded_bytes += out.len() as u64;
        self.check(kernel)
    }

    /// Runs one compute pass of `pipeline` with `bind_group` over `threads` threads (1-D work
    /// folded into rows of at most 65,535 workgroups); returns the row stride in threads that the
    /// shader must use to rebuild its index.
    pub(crate) fn dispatch(
        &mut self,
        kernel: &'static str,
        pipeline: &wgpu::ComputePipeline,
        bind_group: &wgpu::BindGroup,
        threads: u32,
    ) -> Result<(), GpuError> {
        let (x, y) = workgroups(threads)?;
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some(kernel),
            });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(kernel),
                timestamp_writes: None,
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind_group, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.queue.submit([enc.finish()]);
        self.traffic.dispatches += 1;
        self.check(kernel)
    }

    /// The resident crust buffers (after [`Self::sync_crust`]).
    pub fn crust_buffers(&self) -> Option<&CrustBuffers> {
        self.crust.as_ref()
    }

    /// Makes the resident buffers hold `crust`: allocates them for its size and uploads every
    /// field unless the device copy is already in sync with the host change tick `host_tick`
    /// (pass `None` to force the upload).
    ///
    /// Fails with [`GpuError::StaleHostWrite`] instead of uploading when the device holds fields
    /// newer than the host (see [`Self::device_newer`]): the host copy was written without a
    /// pull, and uploading it would lose the device's data.
    pub fn sync_crust(&mut self, crust: &Crust, host_tick: Option<Tick>) -> Result<(), GpuError> {
        let n = crust.len();
        if self.crust.as_ref().is_some_and(|b| b.len == n)
            && host_tick.is_some()
            && self.crust_synced == host_tick
        {
            return Ok(());
        }
        if !self.device_newer.is_empty() {
            return Err(GpuError::StaleHostWrite(self.device_newer));
        }
        if self.crust.as_ref().is_none_or(|b| b.len != n) {
            let b = CrustBuffers {
                len: n,
                elevation_km: self.storage_buffer("crust elevation_km", 4 * n),
                crust_type: self.storage_buffer("crust crust_type (u8 x4)", n),
                age_my: self.storage_buffer("crust age_my", 4 * n),
                orogeny: self.storage_buffer("crust orogeny (u8 x4)", n),
                orogeny_age_my: self.storage_buffer("crust orogeny_age_my", 4 * n),
                fold_dir: self.storage_buffer("crust fold_dir", 12 * n),
                thickness_km: self.storage_buffer("crust thickness_km", 4 * n),
                ridge_dir: self.storage_buffer("crust ridge_dir", 12 * n),
                plate: self.storage_buffer("crust plate", 4 * n),
            };
            self.crust = Some(b);
            self.erosion.forget_bind_group();
            self.aging.forget_bind_group();
            self.uplift.forget_bind_groups();
            self.collision.forget_bind_group();
            self.gather.forget_bind_group();
            self.reduce.forget_bind_group();
        }
        let Some(b) = self.crust.take() else {
            return Err(GpuError::Kernel {
                kernel: "crust upload",
                message: "no crust buffers".into(),
            });
        };
        self.upload_fields(&b, crust, FieldMask::EVERY_FIELD);
        self.crust = Some(b);
        self.crust_synced = host_tick;
        self.traffic.crust_uploads += 1;
        self.check("crust upload")
    }

    /// Records that the device copy of the crust equals the host copy as of change tick `tick`.
    pub fn mark_crust_synced(&mut self, tick: Tick) {
        self.crust_synced = Some(tick);
    }

    /// Forgets the sync state, so the next kernel uploads the whole crust.
    pub fn invalidate_crust(&mut self) {
        self.crust_synced = None;
    }

    /// The resident fields the device holds newer than the host [`Crust`] (written by kernels
    /// since the last pull).
    pub fn device_newer(&self) -> FieldMask {
        self.device_newer
    }

    /// Records that a kernel wrote `fields` on the device; with [`Self::eager_sync`] pulls them
    /// into `crust` at once. Pass the crust through `bypass_change_detection` (a pull is not a
    /// host write).
    pub fn note_device_write(
        &mut self,
        fields: FieldMask,
        crust: &mut Crust,
    ) -> Result<(), GpuError> {
        self.device_newer |= fields;
        if self.eager_sync {
            self.pull(crust, FieldMask::ALL)?;
        }
        Ok(())
    }

    /// Uploads the fields of `fields` of `crust` whole into the resident buffers `b` (the full
    /// upload of [`Self::sync_crust`] and the declared one of [`Self::note_host_write`]).
    fn upload_fields(&mut self, b: &CrustBuffers, crust: &Crust, fields: FieldMask) {
        let has = |f: FieldMask| fields.and(f) == f;
        if has(FieldMask::ELEVATION) {
            self.upload(&b.elevation_km, bytemuck::cast_slice(&crust.elevation_km));
        }
        if has(FieldMask::AGE) {
            self.upload(&b.age_my, bytemuck::cast_slice(&crust.age_my));
        }
        if has(FieldMask::OROGENY) {
            self.upload(&b.orogeny, bytemuck::cast_slice(&crust.orogeny));
        }
        if has(FieldMask::OROGENY_AGE) {
            self.upload(
                &b.orogeny_age_my,
                bytemuck::cast_slice(&crust.orogeny_age_my),
            );
        }
        if has(FieldMask::FOLD_DIR) {
            self.upload(&b.fold_dir, bytemuck::cast_slice(&crust.fold_dir));
        }
        if has(FieldMask::THICKNESS) {
            self.upload(&b.thickness_km, bytemuck::cast_slice(&crust.thickness_km));
        }
        if has(FieldMask::RIDGE_DIR) {
            self.upload(&b.ridge_dir, bytemuck::cast_slice(&crust.ridge_dir));
        }
        if has(FieldMask::PLATE) {
            self.upload(&b.plate, bytemuck::cast_slice(&crust.plate));
        }
        if has(FieldMask::CRUST_TYPE) {
            self.upload(&b.crust_type, bytemuck::cast_slice(&crust.crust_type));
        }
    }

    /// Marks `fields` newer on the device (a kernel wrote them) and pulls them into `crust` at
    /// once (tests and the kernels' `read_back` helpers; the systems leave them on the device).
    pub fn pull_written(&mut self, fields: FieldMask, crust: &mut Crust) -> Result<(), GpuError> {
        self.device_newer |= fields;
        self.pull(crust, fields)
    }

    /// Whether a host write of `fields` into a crust of `len` samples whose change tick is
    /// `before` can be declared (see [`write_crust_fields`]): the device copy is in sync with
    /// the host as of `before` and holds none of `fields` newer.
    pub fn can_declare_host_write(&self, fields: FieldMask, len: usize, before: Tick) -> bool {
        self.crust_synced == Some(before)
            && self.crust.as_ref().is_some_and(|b| b.len == len)
            && self.device_newer.and(fields).is_empty()
    }

    /// After a declared host write (see [`Self::can_declare_host_write`]): uploads the fields of
    /// `fields` of `crust` whole and records the device in sync with the host change tick
    /// `after` (the tick the write moved the crust to). The other fields were not written, so
    /// the device's copies (newer or not) stay as they are.
    pub fn note_host_write(
        &mut self,
        crust: &Crust,
        fields: FieldMask,
        after: Tick,
    ) -> Result<(), GpuError> {
        let Some(b) = self.crust.take() else {
            return Err(GpuError::Kernel {
                kernel: "crust field upload",
                message: "no crust buffers".into(),
            });
        };
        if b.len != crust.len() || !self.device_newer.and(fields).is_empty() {
            let message = format!(
                "declared write of {fields:?}: host {} samples, device {}, device newer {:?}",
                crust.len(),
                b.len,
                self.device_newer
            );
            self.crust = Some(b);
            return Err(GpuError::Kernel {
                kernel: "crust field upload",
                message,
            });
        }
        self.upload_fields(&b, crust, fields);
        self.crust = Some(b);
        self.crust_synced = Some(after);
        self.check("crust field upload")
    }

    /// The host is authoritative again (a new crust was installed: resampling, load): forgets
    /// which fields the device held newer.
    pub fn supersede_device(&mut self) {
        self.device_newer = FieldMask::NONE;
    }

    /// Downloads the fields of `mask` that the device holds newer into `crust` and clears their
    /// bits; fields already in sync cost nothing. Write to the crust through
    /// `bypass_change_detection` (or [`sync_crust_to_host`]): a pull must not move the crust's
    /// change tick, or the next kernel would upload the whole crust again.
    pub fn pull(&mut self, crust: &mut Crust, mask: FieldMask) -> Result<(), GpuError> {
        const KERNEL: &str = "crust pull";
        let want = self.device_newer.and(mask);
        if want.is_empty() {
            return Ok(());
        }
        let Some((n, z, age, og, oga, fold)) = self.crust.as_ref().map(|b| {
            (
                b.len,
                b.elevation_km.clone(),
                b.age_my.clone(),
                b.orogeny.clone(),
                b.orogeny_age_my.clone(),
                b.fold_dir.clone(),
            )
        }) else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "the device holds newer fields but no crust buffers".into(),
            });
        };
        if crust.len() != n {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: format!("host crust has {} samples, device crust {n}", crust.len()),
            });
        }
        if want.contains(FieldMask::ELEVATION) {
            self.download(
                KERNEL,
                &z,
                bytemuck::cast_slice_mut(&mut crust.elevation_km),
            )?;
            self.device_newer.0 &= !FieldMask::ELEVATION.0;
        }
        if want.contains(FieldMask::AGE) {
            self.download(KERNEL, &age, bytemuck::cast_slice_mut(&mut crust.age_my))?;
            self.device_newer.0 &= !FieldMask::AGE.0;
        }
        if want.contains(FieldMask::OROGENY_AGE) {
            self.download(
                KERNEL,
                &oga,
                bytemuck::cast_slice_mut(&mut crust.orogeny_age_my),
            )?;
            self.device_newer.0 &= !FieldMask::OROGENY_AGE.0;
        }
        if want.contains(FieldMask::FOLD_DIR) {
            self.download(KERNEL, &fold, bytemuck::cast_slice_mut(&mut crust.fold_dir))?;
            self.device_newer.0 &= !FieldMask::FOLD_DIR.0;
        }
        if want.contains(FieldMask::OROGENY) {
            let mut scratch = std::mem::take(&mut self.orogeny_scratch);
            scratch.resize(n, 0);
            let r = self.download(KERNEL, &og, &mut scratch);
            let decoded = r.and_then(|()| decode_orogeny(&scratch, &mut crust.orogeny, KERNEL));
            self.orogeny_scratch = scratch;
            decoded?;
            self.device_newer.0 &= !FieldMask::OROGENY.0;
        }
        Ok(())
    }
}

/// Decodes the device's orogeny bytes into `out`; errors name `kernel`.
pub(crate) fn decode_orogeny(
    bytes: &[u8],
    out: &mut [crate::resources::Orogeny],
    kernel: &'static str,
) -> Result<(), GpuError> {
    use crate::resources::Orogeny;
    let mut bad = None;
    for (i, (o, &b)) in out.iter_mut().zip(bytes).enumerate() {
        *o = match b {
            0 => Orogeny::None,
            1 => Orogeny::Andean,
            2 => Orogeny::Himalayan,
            _ => {
                bad = Some((i, b));
                Orogeny::None
            }
        };
    }
    match bad {
        Some((i, b)) => Err(GpuError::Kernel {
            kernel,
            message: format!("orogeny code {b} at sample {i}"),
        }),
        None => Ok(()),
    }
}

/// Pulls the fields of `mask` that the device holds newer into the world's [`Crust`] (without
/// moving its change tick); does nothing on the CPU backend. Call it before any CPU code reads
/// device-written fields or writes the crust (see docs/gpu-residency.md).
pub fn sync_crust_to_host(world: &mut World, mask: FieldMask) -> Result<(), GpuError> {
    if world
        .get_resource::<GpuContext>()
        .is_none_or(|g| g.device_newer.and(mask).is_empty())
    {
        return Ok(());
    }
    world.resource_scope(|world, mut gpu: Mut<GpuContext>| {
        match world.get_resource_mut::<Crust>() {
            Some(mut crust) => gpu.pull(crust.bypass_change_detection(), mask),
            None => Ok(()),
        }
    })
}

/// Writes the host [`Crust`] with `write`, which must change only the fields of `fields`; on the
/// GPU backend keeps the device copy current without a full upload when it can. If the device
/// was in sync with the host before the write and holds none of `fields` newer, `write` runs
/// on the host copy as it is (fields the device holds newer stay stale there and on the device)
/// and only `fields` go up afterwards ([`GpuContext::note_host_write`]; 4 B/sample for the
/// plate ids). Otherwise every stale field is pulled first and the next kernel uploads the
/// whole crust, as for any other host write. The crust's change tick moves as usual. A `write`
/// that changes a field outside `fields` leaves the device with old data there: declare every
/// field written.
pub fn write_crust_fields(
    world: &mut World,
    fields: FieldMask,
    write: impl FnOnce(&mut Crust),
) -> Result<(), GpuError> {
    let Some((before, len)) = world
        .get_resource_ref::<Crust>()
        .map(|c| (c.last_changed(), c.len()))
    else {
        return Ok(());
    };
    let declared = world
        .get_resource::<GpuContext>()
        .is_some_and(|g| g.failure.is_none() && g.can_declare_host_write(fields, len, before));
    if !declared {
        sync_crust_to_host(world, FieldMask::ALL)?;
    }
    let after = {
        let mut crust = world.resource_mut::<Crust>();
        write(&mut crust);
        crust.last_changed()
    };
    if !declared {
        return Ok(());
    }
    world.resource_scope(|world, mut gpu: Mut<GpuContext>| {
        gpu.note_host_write(world.resource::<Crust>(), fields, after)
    })
}

/// [`write_crust_fields`] from an exclusive system: on failure records the error in the context
/// (the step then stops with it) and returns false (`write` may not have run).
pub fn write_crust_fields_or_record(
    world: &mut World,
    fields: FieldMask,
    write: impl FnOnce(&mut Crust),
) -> bool {
    match write_crust_fields(world, fields, write) {
        Ok(()) => true,
        Err(e) => {
            tracing::error!("{e}");
            if let Some(mut g) = world.get_resource_mut::<GpuContext>()
                && g.failure.is_none()
            {
                g.failure = Some(e);
            }
            false
        }
    }
}

/// [`sync_crust_to_host`] from an exclusive system: on failure records the error in the context
/// (the step then stops with it) and returns false.
pub fn sync_crust_to_host_or_record(world: &mut World, mask: FieldMask) -> bool {
    match sync_crust_to_host(world, mask) {
        Ok(()) => true,
        Err(e) => {
            tracing::error!("{e}");
            if let Some(mut g) = world.get_resource_mut::<GpuContext>()
                && g.failure.is_none()
            {
                g.failure = Some(e);
            }
            false
        }
    }
}

/// From a system: pulls the fields of `mask` into `crust` (without moving its change tick).
/// On failure records the error in the context (the step then stops with it) and returns false.
pub fn pull_or_record(
    gpu: &mut GpuContext,
    crust: &mut impl DetectChangesMut<Inner = Crust>,
    mask: FieldMask,
) -> bool {
    if gpu.device_newer.and(mask).is_empty() {
        return true;
    }
    if gpu.failure.is_some() {
        return false;
    }
    match gpu.pull(crust.bypass_change_detection(), mask) {
        Ok(()) => true,
        Err(e) => {
            tracing::error!("{e}");
            gpu.failure = Some(e);
            false
        }
    }
}

/// Workgroup counts (x, y) for `threads` threads.
pub(crate) fn workgroups(threads: u32) -> Result<(u32, u32), GpuError> {
    let groups = threads.div_ceil(WORKGROUP_SIZE).max(1);
    let x = groups.min(ROW_GROUPS);
    let y = groups.div_ceil(ROW_GROUPS);
    if y > ROW_GROUPS {
        return Err(GpuError::TooLarge(format!(
            "{threads} threads do not fit in one dispatch"
        )));
    }
    Ok((x, y))
}

/// Workgroups per dispatch row; the shader's `row_stride` is this times [`WORKGROUP_SIZE`].
pub(crate) const ROW_GROUPS: u32 = 65_535;

/// Threads per dispatch row (the `row_stride` uniform of every kernel).
pub const ROW_STRIDE: u32 = ROW_GROUPS * WORKGROUP_SIZE;

/// A compute pipeline for `wgsl` (prefixed with [`COMMON_WGSL`]) with entry point `main` and
/// the layout derived from the shader.
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    wgsl: &str,
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(shader_source(wgsl).into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A uniform buffer holding `data`.
pub(crate) fn uniform_buffer(device: &wgpu::Device, label: &str, bytes: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// A bind group entry for a whole buffer.
pub(crate) fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

/// Runs a GPU kernel from a system: on failure, records the error in the context (the
/// simulation stops with it at the end of the step) and returns false so the caller runs the
/// CPU reference for this step instead.
pub fn run_or_record(
    ctx: &mut GpuContext,
    f: impl FnOnce(&mut GpuContext) -> Result<(), GpuError>,
) -> bool {
    if ctx.failure.is_some() {
        return false;
    }
    match f(ctx) {
        Ok(()) => true,
        Err(e) => {
            tracing::error!("{e}");
            ctx.invalidate_crust();
            ctx.failure = Some(e);
            false
        }
    }
}
