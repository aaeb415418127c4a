//! The choice of compute backend: what the user asked for ([`BackendChoice`]), what runs
//! ([`ComputeBackend`]), the adapter search ([`select_backend`]) and the errors of the GPU
//! backend ([`GpuError`]).

use bevy_ecs::prelude::*;

use super::context::GpuContext;
use super::residency::FieldMask;

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
    /// them first with [`sync_crust_to_host`](crate::gpu::sync_crust_to_host) or [`GpuContext::pull`]); uploading the host copy
    /// would silently lose the device's newer data.
    #[error(
        "the host crust was written while the device held newer fields ({0:?}); \
         pull them first (gpu::sync_crust_to_host) before writing the crust"
    )]
    StaleHostWrite(FieldMask),
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
pub(crate) fn block_on<F: std::future::Future>(f: F) -> F::Output {
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
