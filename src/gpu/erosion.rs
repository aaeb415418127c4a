//! Host side of `shaders/erosion.wgsl`: continental erosion, oceanic damping and sediment
//! accretion on the resident elevation buffer. The CPU reference is [`erosion_cpu`] (the very
//! function the CPU backend runs, in `src/systems/erosion.rs`).

use crate::gpu::{GpuContext, GpuError, ROW_STRIDE, compute_pipeline, entry, uniform_buffer};
pub use crate::systems::erosion::{ErosionRates, erosion_cpu};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/erosion.wgsl");

/// Uniforms of one erosion step. Keep in sync with `ErosionUniforms` in shaders/erosion.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ErosionUniforms {
    /// z_c, km.
    pub max_elevation_km: f32,
    /// z_a, km.
    pub abyssal_elevation_km: f32,
    /// z_t, km.
    pub trench_elevation_km: f32,
    /// ε_c·δt, km.
    pub erosion_km: f32,
    /// exp(−ε_o/|z_t|·δt).
    pub damping_factor: f32,
    /// ε_t·δt, km.
    pub sediment_km: f32,
    /// Samples.
    pub count: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
}

impl ErosionUniforms {
    /// The uniforms for `rates` over `count` samples (the f64 rates rounded to f32).
    pub fn new(rates: &ErosionRates, count: u32) -> Self {
        Self {
            max_elevation_km: rates.z_c as f32,
            abyssal_elevation_km: rates.z_a as f32,
            trench_elevation_km: rates.z_t as f32,
            erosion_km: rates.erosion_km as f32,
            damping_factor: rates.damping_factor as f32,
            sediment_km: rates.sediment_km as f32,
            count,
            row_stride: ROW_STRIDE,
        }
    }
}

/// Pipeline, uniform buffer and bind group of the kernel.
pub(crate) struct ErosionKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    bind_group: Option<wgpu::BindGroup>,
}

impl ErosionKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, "erosion", WGSL),
            uniforms: uniform_buffer(
                device,
                "erosion uniforms",
                std::mem::size_of::<ErosionUniforms>(),
            ),
            bind_group: None,
        }
    }
    pub(crate) fn forget_bind_group(&mut self) {
        self.bind_group = None;
    }
}

/// One erosion step on the resident crust buffers (call [`GpuContext::sync_crust`] first).
pub fn erosion_dispatch(ctx: &mut GpuContext, rates: &ErosionRates) -> Result<(), GpuError> {
    let Some(b) = ctx.crust_buffers() else {
        return Err(GpuError::Kernel {
            kernel: "erosion",
            message: "the crust is not on the device".into(),
        });
    };
    let n = b.len as u32;
    if ctx.erosion.bind_group.is_none() {
        let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("erosion bindings"),
            layout: &ctx.erosion.pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &ctx.erosion.uniforms),
                entry(1, &b.elevation_km),
                entry(2, &b.crust_type),
            ],
        });
        ctx.erosion.bind_group = Some(bg);
    }
    let u = ErosionUniforms::new(rates, n);
    let (pipeline, uniforms) = (ctx.erosion.pipeline.clone(), ctx.erosion.uniforms.clone());
    ctx.upload(&uniforms, bytemuck::bytes_of(&u));
    let Some(bg) = ctx.erosion.bind_group.clone() else {
        return Ok(());
    };
    ctx.dispatch("erosion", &pipeline, &bg, n)
}
