//! The [`GpuContext`] resource: the wgpu device and queue, the error log, the bytes that crossed
//! the bus ([`GpuTraffic`]), the kernels made on first use ([`Kernel`]) and the residency state of
//! the crust (its methods are in [`super::residency`]).

use std::any::{Any, TypeId};
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use bevy_ecs::change_detection::Tick;
use bevy_ecs::prelude::*;

use super::backend::{GpuError, block_on};
use super::helpers::workgroups;
use super::residency::{CrustBuffers, FieldMask};

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
    /// Isostasy passes (the elevation from the crust) run on the device.
    pub isostasy_passes: u64,
    /// Land diffusion passes (one per call, whatever its sub-steps) run on the device.
    pub diffusion_passes: u64,
}

/// A kernel's pipeline and whatever it keeps on the device between dispatches (uniform buffers,
/// cached bind groups), made on first use by [`GpuContext::with_kernel`]. Adding a kernel means
/// writing its host module and implementing this; nothing else changes.
pub trait Kernel: Send + Sync + 'static {
    /// Builds the pipeline (and the kernel's own buffers) on `device`.
    fn new(device: &wgpu::Device) -> Self
    where
        Self: Sized;
    /// The resident crust buffers were replaced: drop any bind group that names them.
    fn forget_bind_groups(&mut self) {}
}

/// A cached kernel, as the cache holds it.
trait CachedKernel: Any + Send + Sync {
    fn forget(&mut self);
}

impl<K: Kernel> CachedKernel for K {
    fn forget(&mut self) {
        self.forget_bind_groups();
    }
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
    /// The kernels made so far, by type.
    kernels: BTreeMap<TypeId, Box<dyn CachedKernel>>,
    pub(super) crust: Option<CrustBuffers>,
    pub(super) crust_synced: Option<Tick>,
    pub(super) device_newer: FieldMask,
    staging: Option<wgpu::Buffer>,
    pub(super) orogeny_scratch: Vec<u8>,
    /// Pull every field a kernel wrote right after the kernel (the behaviour before lazy host
    /// sync; used by tests to check that lazy sync changes no result). Off by default.
    pub eager_sync: bool,
    /// Bytes moved and dispatches made.
    pub traffic: GpuTraffic,
    /// The first failure of a kernel run by a system; the simulation stops with it.
    pub failure: Option<GpuError>,
}

impl GpuContext {
    /// Opens a device on `adapter`. Kernel pipelines are built on first use.
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
        let ctx = Self {
            device,
            queue,
            adapter: info,
            errors,
            kernels: BTreeMap::new(),
            crust: None,
            crust_synced: None,
            device_newer: FieldMask::NONE,
            staging: None,
            orogeny_scratch: Vec::new(),
            eager_sync: false,
            traffic: GpuTraffic::default(),
            failure: None,
        };
        ctx.check("device")?;
        Ok(ctx)
    }

    /// Runs `f` with the kernel `K` (built on first use) and the context. The kernel is taken
    /// out of the cache for the call, so `f` may use the context freely.
    pub fn with_kernel<K: Kernel, R>(&mut self, f: impl FnOnce(&mut Self, &mut K) -> R) -> R {
        let id = TypeId::of::<K>();
        let cached = self.kernels.remove(&id).and_then(|b| {
            let any: Box<dyn Any + Send + Sync> = b;
            any.downcast::<K>().ok()
        });
        let mut kernel = cached.unwrap_or_else(|| Box::new(K::new(&self.device)));
        let out = f(self, &mut kernel);
        self.kernels.insert(id, kernel);
        out
    }

    /// Keeps `e` as the failure the simulation stops with at the end of the step (the first one
    /// of a step wins). Not logged here: whoever stops reports it, once.
    pub fn record_failure(&mut self, e: GpuError) {
        tracing::debug!("GPU failure recorded: {e}");
        if self.failure.is_none() {
            self.failure = Some(e);
        }
    }

    /// Tells every kernel made so far that the resident crust buffers were replaced.
    pub(super) fn forget_bind_groups(&mut self) {
        for k in self.kernels.values_mut() {
            k.forget();
        }
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
            ctx.invalidate_crust();
            ctx.record_failure(e);
            false
        }
    }
}
