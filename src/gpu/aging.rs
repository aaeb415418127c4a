//! Host side of `shaders/aging.wgsl`: crust and orogeny ages grow by the time step, on the
//! resident buffers. The CPU reference is [`aging_cpu`](crate::systems::aging::aging_cpu) (the function the CPU backend runs, in
//! `src/systems/aging.rs`); both do the same f32 additions, so they agree bit for bit.

use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};

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

impl Kernel for AgingKernel {
    fn new(device: &wgpu::Device) -> Self {
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
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

/// One aging step of `dt_my` on the resident crust buffers (call [`GpuContext::sync_crust`]
/// first).
pub fn aging_dispatch(ctx: &mut GpuContext, dt_my: f32) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut AgingKernel| {
        let Some(b) = ctx.crust_buffers() else {
            return Err(GpuError::Kernel {
                kernel: "aging",
                message: "the crust is not on the device".into(),
            });
        };
        let n = b.len as u32;
        if k.bind_group.is_none() {
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("aging bindings"),
                layout: &k.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &k.uniforms),
                    entry(1, &b.age_my),
                    entry(2, &b.orogeny_age_my),
                    entry(3, &b.orogeny),
                ],
            });
            k.bind_group = Some(bg);
        }
        let u = AgingUniforms {
            dt_my,
            count: n,
            row_stride: ROW_STRIDE,
            _pad: 0,
        };
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        let Some(bg) = k.bind_group.clone() else {
            return Ok(());
        };
        ctx.dispatch("aging", &pipeline, &bg, n)
    })
}
