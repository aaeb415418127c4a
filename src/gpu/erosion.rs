//! Host side of `shaders/erosion.wgsl`: continental erosion, oceanic damping and sediment
//! accretion on the resident elevation buffer. The CPU reference is [`erosion_cpu`](crate::systems::erosion::erosion_cpu) (the very
//! function the CPU backend runs, in `src/systems/erosion.rs`).

use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};
use crate::resources::Params;

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/erosion.wgsl");

/// The per-step constants of [`erode_sample`](crate::systems::erosion::erode_sample).
#[derive(Clone, Copy, Debug)]
pub struct ErosionRates {
    pub(crate) z_c: f64,
    pub(crate) z_a: f64,
    pub(crate) z_t: f64,
    pub(crate) erosion_km: f64,
    pub(crate) damping_factor: f64,
    pub(crate) sediment_km: f64,
}

impl ErosionRates {
    /// Rates for one time step of the given parameters.
    pub fn new(params: &Params) -> Self {
        let dt = params.time.time_step_my;
        let o = &params.ocean;
        Self {
            z_c: params.continent.max_elevation_km,
            z_a: o.abyssal_elevation_km,
            z_t: o.trench_elevation_km,
            erosion_km: params.continent.erosion_mm_per_yr * dt,
            damping_factor: (-(o.damping_mm_per_yr / o.trench_elevation_km.abs().max(1e-9)) * dt)
                .exp(),
            sediment_km: o.sediment_accretion_mm_per_yr * dt,
        }
    }
}

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

impl Kernel for ErosionKernel {
    fn new(device: &wgpu::Device) -> Self {
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
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

/// One erosion step on the resident crust buffers (call [`GpuContext::sync_crust`] first).
pub fn erosion_dispatch(ctx: &mut GpuContext, rates: &ErosionRates) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut ErosionKernel| {
        let Some(b) = ctx.crust_buffers() else {
            return Err(GpuError::Kernel {
                kernel: "erosion",
                message: "the crust is not on the device".into(),
            });
        };
        let n = b.len as u32;
        if k.bind_group.is_none() {
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("erosion bindings"),
                layout: &k.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &k.uniforms),
                    entry(1, &b.elevation_km),
                    entry(2, &b.crust_type),
                ],
            });
            k.bind_group = Some(bg);
        }
        let u = ErosionUniforms::new(rates, n);
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        let Some(bg) = k.bind_group.clone() else {
            return Ok(());
        };
        ctx.dispatch("erosion", &pipeline, &bg, n)
    })
}
