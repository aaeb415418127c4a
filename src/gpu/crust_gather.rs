//! Host side of `shaders/crust_gather.wgsl`: the resident elevation at a list of sample indices
//! (the vertices under the front points, which `track_fronts` locates on the CPU), so a step
//! reads back 4 bytes per index instead of the whole field. The CPU reference is
//! [`crust_gather_cpu`] (indexing the host array); the kernel copies raw 32-bit words, so both
//! agree bit for bit.

use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/crust_gather.wgsl");

/// Uniforms of one gather. Keep in sync with `GatherUniforms` in shaders/crust_gather.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GatherUniforms {
    /// Indices to gather.
    pub count: u32,
    /// Samples of the resident crust.
    pub samples: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// Pipeline, uniforms and the index/output buffers (grown on demand).
pub(crate) struct GatherKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    buffers: Option<(usize, wgpu::Buffer, wgpu::Buffer)>,
    bind_group: Option<wgpu::BindGroup>,
}

impl Kernel for GatherKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, "crust_gather", WGSL),
            uniforms: uniform_buffer(
                device,
                "crust_gather uniforms",
                std::mem::size_of::<GatherUniforms>(),
            ),
            buffers: None,
            bind_group: None,
        }
    }
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

/// CPU reference: `elevation[index[k]]` for each k.
pub fn crust_gather_cpu(elevation_km: &[f32], index: &[u32]) -> Vec<f32> {
    index.iter().map(|&i| elevation_km[i as usize]).collect()
}

/// The resident elevation at `index` (call [`GpuContext::sync_crust`] first). Indices must be
/// below the crust's sample count.
pub fn crust_gather_gpu(ctx: &mut GpuContext, index: &[u32]) -> Result<Vec<f32>, GpuError> {
    ctx.with_kernel(|ctx, k: &mut GatherKernel| {
        const KERNEL: &str = "crust_gather";
        let Some(b) = ctx.crust_buffers() else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "the crust is not on the device".into(),
            });
        };
        let (n, elevation) = (b.len, b.elevation_km.clone());
        if let Some(&bad) = index.iter().find(|&&i| i as usize >= n) {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: format!("index {bad} out of {n} samples"),
            });
        }
        let m = index.len();
        if m == 0 {
            return Ok(Vec::new());
        }
        if k.buffers.as_ref().is_none_or(|(cap, _, _)| *cap < m) {
            let cap = m.next_power_of_two();
            let idx = ctx.storage_buffer("crust_gather index", 4 * cap);
            let out = ctx.storage_buffer("crust_gather elevation out", 4 * cap);
            k.buffers = Some((cap, idx, out));
            k.bind_group = None;
        }
        let Some((_, idx, out)) = k.buffers.clone() else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "no buffers".into(),
            });
        };
        if k.bind_group.is_none() {
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("crust_gather bindings"),
                layout: &k.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &k.uniforms),
                    entry(1, &elevation),
                    entry(2, &idx),
                    entry(3, &out),
                ],
            });
            k.bind_group = Some(bg);
        }
        let u = GatherUniforms {
            count: m as u32,
            samples: n as u32,
            row_stride: ROW_STRIDE,
            _pad: 0,
        };
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        ctx.upload(&idx, bytemuck::cast_slice(index));
        let Some(bg) = k.bind_group.clone() else {
            return Ok(Vec::new());
        };
        ctx.dispatch(KERNEL, &pipeline, &bg, m as u32)?;
        let mut z = vec![f32::NAN; m];
        ctx.download(KERNEL, &out, bytemuck::cast_slice_mut(&mut z))?;
        Ok(z)
    })
}
