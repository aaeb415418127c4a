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

/// The adapters wgpu finds (on the backends `WGPU_BACKEND` allows), hardware first, and the
/// backends searched.
fn sorted_adapters() -> (Vec<wgpu::Adapter>, wgpu::Backends) {
    let desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    let backends = desc.backends;
    let instance = wgpu::Instance::new(desc);
    let mut adapters = block_on(instance.enumerate_adapters(backends));
    adapters.sort_by_key(|a| type_rank(a.get_info().device_type));
    (adapters, backends)
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
    let (mut adapters, backends) = sorted_adapters();
    let hardware = adapters
        .iter()
        .position(|a| a.get_info().device_type != wgpu::DeviceType::Cpu);
    let pick = match choice {
        BackendChoice::Auto => hardware,
        _ => (!adapters.is_empty()).then_some(0),
    };
    let Some(k) = pick else {
        if choice == BackendChoice::Auto {
            let survey = AdapterSurvey {
                hardware: None,
                software: adapters.first().map(|a| a.get_info().name),
                backends: format!("{backends:?}"),
            };
            return Ok(SelectedBackend {
                backend: ComputeBackend::Cpu,
                context: None,
                note: survey.cpu_note(),
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

/// What the adapter search of [`select_backend`] finds, without opening a device: whether
/// `auto` would pick a GPU. A program can take it in a child process
/// ([`AdapterSurvey::to_text`], [`AdapterSurvey::from_text`]), so that a machine with no
/// hardware GPU never loads a Vulkan driver into the simulation's process (Mesa's lavapipe
/// brings LLVM: about 50 MB of resident memory, for nothing when the CPU runs the kernels).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AdapterSurvey {
    /// The name of the adapter `auto` would open (a hardware one), if any.
    pub hardware: Option<String>,
    /// The best software adapter's name (lavapipe), when there is no hardware one.
    pub software: Option<String>,
    /// The wgpu backends searched (as wgpu prints them).
    pub backends: String,
}

impl AdapterSurvey {
    /// Enumerates the adapters as [`select_backend`] does (`WGPU_BACKEND` limits the search).
    pub fn take() -> Self {
        let (adapters, backends) = sorted_adapters();
        let name = |a: &wgpu::Adapter| a.get_info().name;
        let hardware = adapters
            .iter()
            .find(|a| a.get_info().device_type != wgpu::DeviceType::Cpu)
            .map(name);
        Self {
            software: if hardware.is_none() {
                adapters.first().map(name)
            } else {
                None
            },
            hardware,
            backends: format!("{backends:?}"),
        }
    }

    /// The note [`select_backend`] gives under [`BackendChoice::Auto`] when it finds no
    /// hardware adapter (and so runs on the CPU).
    pub fn cpu_note(&self) -> String {
        match &self.software {
            Some(name) => {
                format!("{SOFTWARE_ONLY} (only the software adapter {name}); compute backend: cpu")
            }
            None => format!(
                "{}; compute backend: cpu",
                GpuError::NoAdapter(format!(" for backends {}", self.backends))
            ),
        }
    }

    /// The survey as lines of text (`hardware`, `software` and `backends`, each a tab and its
    /// value; a missing adapter has no line).
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let mut line = |key: &str, v: &str| {
            // (An adapter name holds no tab or newline; one that did would lose them.)
            let v: String = v
                .chars()
                .map(|c| if c.is_control() { ' ' } else { c })
                .collect();
            out.push_str(&format!("{key}\t{v}\n"));
        };
        if let Some(h) = &self.hardware {
            line("hardware", h);
        }
        if let Some(s) = &self.software {
            line("software", s);
        }
        line("backends", &self.backends);
        out
    }

    /// Reads [`Self::to_text`]; `None` for anything else (no `backends` line, an unknown key).
    pub fn from_text(text: &str) -> Option<Self> {
        let mut survey = Self::default();
        let mut backends = None;
        for line in text.lines().filter(|l| !l.is_empty()) {
            let (key, value) = line.split_once('\t')?;
            match key {
                "hardware" => survey.hardware = Some(value.to_string()),
                "software" => survey.software = Some(value.to_string()),
                "backends" => backends = Some(value.to_string()),
                _ => return None,
            }
        }
        survey.backends = backends?;
        Some(survey)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_adapter_survey_reads_back_from_its_text() {
        for survey in [
            AdapterSurvey {
                hardware: Some("NVIDIA H100".into()),
                software: None,
                backends: "Backends(VULKAN | GL)".into(),
            },
            AdapterSurvey {
                hardware: None,
                software: Some("llvmpipe (LLVM 15.0.6, 256 bits)".into()),
                backends: "Backends(VULKAN)".into(),
            },
            AdapterSurvey {
                hardware: None,
                software: None,
                backends: "Backends(DX12)".into(),
            },
        ] {
            assert_eq!(AdapterSurvey::from_text(&survey.to_text()), Some(survey));
        }
        assert_eq!(AdapterSurvey::from_text(""), None);
        assert_eq!(AdapterSurvey::from_text("hardware\tX\n"), None);
        assert_eq!(AdapterSurvey::from_text("error: no such command\n"), None);
        let none = AdapterSurvey::from_text("backends\tBackends(DX12)\n").expect("survey");
        assert!(none.cpu_note().contains("no GPU adapter found"));
        assert!(none.cpu_note().ends_with("compute backend: cpu"));
    }
}
