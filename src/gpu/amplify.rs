//! Host side of `shaders/amplify.wgsl`: procedural amplification (paper §5) of query points on
//! the device, one invocation per point. The CPU reference is [`amplify_cpu`](crate::amplify::procedural::amplify_cpu) (the function the
//! CPU exports run, in `src/amplify/procedural.rs`); the shader mirrors `amplify_point` in f32,
//! and the two agree within the tolerance of `docs/amplification.md` (`tests/amplify.rs`).
//!
//! The crust table ([`AmplifyVertex`], 48 bytes a sample) goes up once per [`AmplifyGpu`]; the
//! queries ([`AmplifyQuery`], 36 bytes a point) go up and the elevations (4 bytes a point) come
//! back in chunks small enough for the adapter's buffer and dispatch limits, so exports of any
//! size stream through buffers of fixed size. Exemplar primitives are CPU only: the shader
//! ignores the `exemplar` field.

use bytemuck::{Pod, Zeroable};

use crate::gpu::{GpuContext, GpuError, compute_pipeline, entry, uniform_buffer};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/amplify.wgsl");

/// One crust sample as the amplification reads it. Keep in sync with `shaders/amplify.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct AmplifyVertex {
    /// Unit position, world frame.
    pub px: f32,
    /// See `px`.
    pub py: f32,
    /// See `px`.
    pub pz: f32,
    /// Unit tangent along the grain (ridge or fold direction), world frame.
    pub ax: f32,
    /// See `ax`.
    pub ay: f32,
    /// See `ax`.
    pub az: f32,
    /// Crust elevation, metres.
    pub elevation_m: f32,
    /// Oceanic age (oceanic crust) or orogeny age (continental crust), My.
    pub age_my: f32,
    /// Random offset of the primitive along the grain, km.
    pub offset_x_km: f32,
    /// Random offset of the primitive across the grain, km.
    pub offset_y_km: f32,
    /// One of the `KIND_*` constants.
    pub kind: u32,
    /// Exemplar index + 1, or 0 for procedural relief (CPU only; the shader ignores it).
    pub exemplar: u32,
}

/// One point to amplify: its direction and the triangle around it. Keep in sync with
/// `shaders/amplify.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct AmplifyQuery {
    /// Unit direction of the point, world frame.
    pub dx: f32,
    /// See `dx`.
    pub dy: f32,
    /// See `dx`.
    pub dz: f32,
    /// Vertex indices of the containing triangle.
    pub c0: u32,
    /// See `c0`.
    pub c1: u32,
    /// See `c0`.
    pub c2: u32,
    /// Barycentric weights of `c0`, `c1`, `c2` (sum 1).
    pub w0: f32,
    /// See `w0`.
    pub w1: f32,
    /// See `w0`.
    pub w2: f32,
}

/// Global constants of one amplification. Keep in sync with `shaders/amplify.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct AmplifyUniform {
    /// Planet radius, km.
    pub radius_km: f32,
    /// Seed of the noise (32 bits of the planet seed, mixed).
    pub seed: u32,
    /// Multiplies all relief (1 = the model's amplitudes).
    pub relief_scale: f32,
    /// Number of queries (the shader's bound check).
    pub count: u32,
    /// Shortest noise wavelength evaluated, km: finer octaves are left out (an output's pixels
    /// cannot resolve them; see `Amplifier::with_pixel_km`). 0 keeps every octave.
    pub min_wavelength_km: f32,
    /// Padding to 32 bytes (a uniform buffer's struct is read in 16-byte rows).
    pub pad: [u32; 3],
}

/// Threads per workgroup of the kernel (`@workgroup_size` in shaders/amplify.wgsl).
pub const AMPLIFY_WORKGROUP_SIZE: u32 = 64;

/// Default largest number of queries per dispatch (36 MiB of queries, 4 MiB of elevations),
/// lowered further to fit the adapter's limits.
pub const DEFAULT_CHUNK: usize = 1 << 20;

const KERNEL: &str = "amplify";

/// The amplification kernel with one crust table on the device: pipeline, uniform, vertex,
/// query and output buffers, and their bind group. Build it once per crust and call
/// [`AmplifyGpu::run`] for as many batches of queries as needed.
pub struct AmplifyGpu {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    queries: wgpu::Buffer,
    out: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    uniform: AmplifyUniform,
    vertex_count: usize,
    chunk: usize,
}

/// The largest number of queries one dispatch can take on `device`, at most `limit`.
fn chunk_for(device: &wgpu::Device, limit: usize) -> usize {
    let l = device.limits();
    let binding = l.max_storage_buffer_binding_size.min(l.max_buffer_size) as usize;
    let groups = l.max_compute_workgroups_per_dimension as usize * AMPLIFY_WORKGROUP_SIZE as usize;
    limit
        .min(groups)
        .min(binding / std::mem::size_of::<AmplifyQuery>())
        .max(1)
}

impl AmplifyGpu {
    /// Builds the pipeline and uploads `vertices`, with chunks of at most [`DEFAULT_CHUNK`]
    /// queries.
    pub fn new(
        ctx: &mut GpuContext,
        vertices: &[AmplifyVertex],
        uniform: &AmplifyUniform,
    ) -> Result<Self, GpuError> {
        Self::with_chunk_limit(ctx, vertices, uniform, DEFAULT_CHUNK)
    }

    /// [`Self::new`] with chunks of at most `max_chunk` queries (the adapter's limits may lower
    /// it further; tests use small chunks to exercise the chunking).
    pub fn with_chunk_limit(
        ctx: &mut GpuContext,
        vertices: &[AmplifyVertex],
        uniform: &AmplifyUniform,
        max_chunk: usize,
    ) -> Result<Self, GpuError> {
        let vsize = std::mem::size_of_val(vertices);
        let limits = ctx.device.limits();
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if vsize as u64 > max_binding {
            return Err(GpuError::TooLarge(format!(
                "the amplification table ({} samples, {vsize} bytes) exceeds the adapter's \
                 storage binding limit of {max_binding} bytes; use --backend cpu",
                vertices.len()
            )));
        }
        let chunk = chunk_for(&ctx.device, max_chunk);
        let pipeline = compute_pipeline(&ctx.device, KERNEL, WGSL);
        let uniforms = uniform_buffer(
            &ctx.device,
            "amplify uniforms",
            std::mem::size_of::<AmplifyUniform>(),
        );
        // At least one element each: bindings of runtime-sized arrays may not be empty.
        let vbuf = ctx.storage_buffer(
            "amplify vertices (AmplifyVertex)",
            vsize.max(std::mem::size_of::<AmplifyVertex>()),
        );
        let queries = ctx.storage_buffer(
            "amplify queries (AmplifyQuery)",
            chunk * std::mem::size_of::<AmplifyQuery>(),
        );
        let out = ctx.storage_buffer("amplify out_elevation_m", chunk * 4);
        ctx.upload(&vbuf, bytemuck::cast_slice(vertices));
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("amplify bindings"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &uniforms),
                entry(1, &vbuf),
                entry(2, &queries),
                entry(3, &out),
            ],
        });
        ctx.check(KERNEL)?;
        Ok(Self {
            pipeline,
            uniforms,
            queries,
            out,
            bind_group,
            uniform: *uniform,
            vertex_count: vertices.len(),
            chunk,
        })
    }

    /// Queries per dispatch.
    pub fn chunk_len(&self) -> usize {
        self.chunk
    }

    /// The amplified elevation (metres) of every query into `out[..queries.len()]`, one
    /// dispatch per chunk. `out` must be at least as long as `queries`.
    pub fn run(
        &self,
        ctx: &mut GpuContext,
        queries: &[AmplifyQuery],
        out: &mut [f32],
    ) -> Result<(), GpuError> {
        if out.len() < queries.len() {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: format!(
                    "output holds {} values for {} queries",
                    out.len(),
                    queries.len()
                ),
            });
        }
        if self.vertex_count == 0 {
            // No crust: every corner is skipped, so the relief and the base are zero, as
            // `amplify_cpu` gives with no vertices (the device table is a dummy).
            out[..queries.len()].fill(0.0);
            return Ok(());
        }
        for (q, o) in queries.chunks(self.chunk).zip(out.chunks_mut(self.chunk)) {
            let n = q.len();
            let u = AmplifyUniform {
                count: n as u32,
                ..self.uniform
            };
            ctx.upload(&self.uniforms, bytemuck::bytes_of(&u));
            ctx.upload(&self.queries, bytemuck::cast_slice(q));
            let mut enc = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some(KERNEL),
                });
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(KERNEL),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.dispatch_workgroups((n as u32).div_ceil(AMPLIFY_WORKGROUP_SIZE), 1, 1);
            }
            ctx.queue.submit([enc.finish()]);
            ctx.traffic.dispatches += 1;
            ctx.check(KERNEL)?;
            ctx.download(KERNEL, &self.out, bytemuck::cast_slice_mut(&mut o[..n]))?;
        }
        Ok(())
    }
}

/// The amplified elevation (metres) of every query on the device: the GPU counterpart of
/// [`amplify_cpu`](crate::amplify::procedural::amplify_cpu) (the `count` of `uniform` is ignored; each chunk sets its own).
pub fn amplify_gpu(
    ctx: &mut GpuContext,
    vertices: &[AmplifyVertex],
    queries: &[AmplifyQuery],
    uniform: &AmplifyUniform,
) -> Result<Vec<f32>, GpuError> {
    let mut out = vec![0.0f32; queries.len()];
    if queries.is_empty() {
        return Ok(out);
    }
    AmplifyGpu::new(ctx, vertices, uniform)?.run(ctx, queries, &mut out)?;
    Ok(out)
}
