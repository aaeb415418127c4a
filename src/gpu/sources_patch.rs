//! Host side of `shaders/sources_patch.wgsl`: writes the located sources that the host
//! rechecked in f64 (the samples the location kernel left to the CPU, about 1-2%) into the
//! location kernel's output on the device, so the interpolation can read the sources there
//! instead of having all of them uploaded again (stage 3b of docs/gpu-residency.md). The CPU
//! reference is [`sources_patch_cpu`]; the kernel copies raw 32-bit words, so both agree bit for
//! bit. Per resampling, 36 bytes go up per rechecked sample.

use crate::gpu::resample_locate::SampleSource;
use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/sources_patch.wgsl");

const KERNEL: &str = "sources_patch";

/// Uniforms of one patch. Keep in sync with `PatchUniforms` in shaders/sources_patch.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PatchUniforms {
    /// Patches.
    pub count: u32,
    /// Sources (samples) in the target buffer.
    pub samples: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// Pipeline and uniforms.
pub(crate) struct PatchKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
}

impl Kernel for PatchKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, KERNEL, WGSL),
            uniforms: uniform_buffer(
                device,
                "sources_patch uniforms",
                std::mem::size_of::<PatchUniforms>(),
            ),
        }
    }
}

/// The 8 words of a source as the location kernel writes them and the interpolation kernel
/// reads them: slot, plate, suture, flags (1: continental crust lost here), triangle, the three
/// weights' bits.
pub fn source_words(s: &SampleSource) -> [u32; 8] {
    [
        s.slot,
        s.plate,
        s.suture,
        u32::from(s.continental_lost),
        s.triangle,
        s.weights[0].to_bits(),
        s.weights[1].to_bits(),
        s.weights[2].to_bits(),
    ]
}

/// CPU reference: `words[index] = patch` for each `(index, patch)`, in order.
pub fn sources_patch_cpu(words: &mut [[u32; 8]], patches: &[(u32, [u32; 8])]) {
    for &(j, w) in patches {
        words[j as usize] = w;
    }
}

/// Writes `patches` into `target` (8 words a sample, `samples` samples) on the device. Indices
/// must be below `samples` and distinct (the order of two writes to one index is not defined on
/// the device).
pub fn sources_patch_gpu(
    ctx: &mut GpuContext,
    target: &wgpu::Buffer,
    samples: usize,
    patches: &[(u32, [u32; 8])],
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut PatchKernel| {
        let fail = |message: String| GpuError::Kernel {
            kernel: KERNEL,
            message,
        };
        if (target.size() as usize) < 32 * samples {
            return Err(fail(format!(
                "target of {} bytes for {samples} sources",
                target.size()
            )));
        }
        if let Some((bad, _)) = patches.iter().find(|(j, _)| *j as usize >= samples) {
            return Err(fail(format!("index {bad} out of {samples} sources")));
        }
        if patches.is_empty() {
            return Ok(());
        }
        let words: Vec<u32> = patches
            .iter()
            .flat_map(|(j, w)| std::iter::once(*j).chain(w.iter().copied()))
            .collect();
        let buf = ctx.storage_buffer("sources_patch patches", 4 * words.len());
        ctx.upload(&buf, bytemuck::cast_slice(&words));
        let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sources_patch bindings"),
            layout: &k.pipeline.get_bind_group_layout(0),
            entries: &[entry(0, &k.uniforms), entry(1, &buf), entry(2, target)],
        });
        let u = PatchUniforms {
            count: patches.len() as u32,
            samples: samples as u32,
            row_stride: ROW_STRIDE,
            _pad: 0,
        };
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        ctx.dispatch(KERNEL, &pipeline, &bg, patches.len() as u32)
    })
}
