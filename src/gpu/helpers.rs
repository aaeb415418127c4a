//! Helpers shared by the kernels' host modules: the workgroup size and dispatch rows, the shared
//! WGSL, pipeline and buffer constructors, bind-group entries.

use super::backend::GpuError;

/// Threads per workgroup of every per-sample kernel (`WORKGROUP_SIZE` in
/// `shaders/common/bytes.wgsl`).
pub const WORKGROUP_SIZE: u32 = 256;

/// Shared WGSL prepended to every kernel (the files of `shaders/common/`, in name order).
pub const COMMON_WGSL: &str = include_str!("../../shaders/common/bytes.wgsl");

/// The full source of a kernel: [`COMMON_WGSL`] followed by the kernel's own file.
pub fn shader_source(kernel_wgsl: &str) -> String {
    format!("{COMMON_WGSL}\n{kernel_wgsl}")
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
