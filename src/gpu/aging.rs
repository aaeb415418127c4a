//! Host side of `shaders/aging.wgsl`: crust and orogeny ages grow by the time step, on the
//! resident buffers. The CPU reference is [`aging_cpu`] (the function the CPU backend runs, in
//! `src/systems/aging.rs`); both do the same f32 additions, so they agree bit for bit.

use crate::gpu::{GpuContext, GpuError, ROW_STRIDE, compute_pipeline, entry, uniform_buffer};
pub use crate::systems::aging::aging_cpu;

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/aging.wgsl");

/// Uniforms of one aging step. Keep in sync with `AgingUniforms` in shaders/aging.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AgingUniforms {
    /// Time step, My.
    pub dt_my: f32,
    /// Samples.
    pub count: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// Pipeline, uniform buffer and bind group of the kernel.
pub(crate) struct AgingKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    bind_group: Option<wgpu::BindGroup>,
}

impl AgingKernel {
    pub(crate) fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, "aging", WGSL),
            uniforms: uniform_buffer(
                device,
                "aging uniforms",
                std::mem::size_of::<AgingUniforms>(),
            ),
            bind_group: None,
        }
    }
    pub(crate) fn forget_bind_group(&mut self) {
        self.bind_group = None;
    }
}

/// One aging step of `dt_my` on the resident crust buffers (call [`GpuContext::sync_crust`]
/// first).
pub fn aging_dispatch(ctx: &mut GpuContext, dt_my: f32) -> Result<(), GpuError> {
    let Some(b) = ctx.crust_buffers() else {
        return Err(GpuError::Kernel {
            kernel: "aging",
            message: "the crust is not on the device".into(),
        });
    };
    let n = b.len as u32;
    if ctx.aging.bind_group.is_none() {
        let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("aging bindings"),
            layout: &ctx.aging.pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &ctx.aging.uniforms),
                entry(1, &b.age_my),
                entry(2, &b.orogeny_age_my),
                entry(3, &b.orogeny),
            ],
        });
        ctx.aging.bind_group = Some(bg);
    }
    let u = AgingUniforms {
        dt_my,
        count: n,
        row_stride: ROW_STRIDE,
        _pad: 0,
    };
    let (pipeline, uniforms) = (ctx.aging.pipeline.clone(), ctx.aging.uniforms.clone());
    ctx.upload(&uniforms, bytemuck::bytes_of(&u));
    let Some(bg) = ctx.aging.bind_group.clone() else {
        return Ok(());
    };
    ctx.dispatch("aging", &pipeline, &bg, n)
}
