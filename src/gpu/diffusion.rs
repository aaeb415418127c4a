//! Host side of `shaders/diffusion.wgsl`: explicit finite-volume diffusion of the land surface
//! (cotangent weights, the coast held at sea level) on the resident elevation buffer. The CPU
//! reference is [`diffuse_land`](crate::systems::relief::diffusion::diffuse_land) (the function
//! the CPU backend runs, in `src/systems/relief/diffusion.rs`), which also decides the sub-steps
//! and the coast; [`diffuse_land_gpu`](crate::systems::relief::diffusion::diffuse_land_gpu) runs
//! this kernel in its place.
//!
//! What crosses the bus:
//! - **Once per mesh:** the sample graph (CSR start and area, 8 bytes a sample; neighbour and
//!   cotangent weight, 8 bytes a directed edge: about 56 bytes a sample).
//! - **Per call, up:** the elevation to diffuse (4 bytes a sample, into the resident buffer), the
//!   ocean mask (one bit a sample), the coast samples (4 bytes each) and one uniform block per
//!   phase. **Down** ([`diffusion_read_back`]): the diffused elevation (4 bytes a sample: the
//!   sediment router, on the CPU, reads it next) and each coast sample's receipt (4 bytes each).

use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/diffusion.wgsl");

const KERNEL: &str = "diffusion";

/// The sample graph the diffusion runs on (the arrays of the relief graph).
#[derive(Clone, Copy, Debug)]
pub struct DiffusionGraph<'a> {
    /// CSR offsets into `neighbors` (samples + 1).
    pub neighbor_start: &'a [u32],
    /// Neighbours of each sample.
    pub neighbors: &'a [u32],
    /// Cotangent weight of each directed edge (symmetric).
    pub edge_weight: &'a [f32],
    /// Area of each sample, km².
    pub area_km2: &'a [f64],
}

impl DiffusionGraph<'_> {
    /// Samples.
    pub fn len(&self) -> usize {
        self.area_km2.len()
    }
    /// True without samples.
    pub fn is_empty(&self) -> bool {
        self.area_km2.is_empty()
    }
}

/// One diffusion call: the explicit sub-steps and their rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffusionSteps {
    /// κ·Δt_sub, km² (diffusivity times the sub-step).
    pub rate_km2: f64,
    /// Explicit sub-steps.
    pub substeps: u32,
}

/// Uniforms of one phase. Keep in sync with `DiffusionUniforms` in shaders/diffusion.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DiffusionUniforms {
    /// κ·Δt_sub, km².
    pub rate: f32,
    /// Samples.
    pub count: u32,
    /// Coast samples.
    pub coast_count: u32,
    /// 0: start, 1: one sub-step, 2: write the elevation.
    pub phase: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Padding to 32 bytes.
    pub _pad: [u32; 3],
}

/// The graph on the device and what identifies it.
struct GraphBuffers {
    nodes: wgpu::Buffer,
    edges: wgpu::Buffer,
    key: (usize, usize, u64),
}

/// Per-sample scratch: the ocean bits, the two ping-pong elevations, the coast list and its
/// receipts (room for every sample, so they are made once per mesh).
struct Scratch {
    ocean: wgpu::Buffer,
    h_a: wgpu::Buffer,
    h_b: wgpu::Buffer,
    coast: wgpu::Buffer,
    receipts: wgpu::Buffer,
    len: usize,
}

/// Pipeline and buffers of the kernel.
pub(crate) struct DiffusionKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    graph: Option<GraphBuffers>,
    scratch: Option<Scratch>,
    /// Bind groups (h_a → h_b, h_b → h_a).
    bind_groups: Option<[wgpu::BindGroup; 2]>,
    /// Coast samples of the last call (for the read-back).
    coast_count: usize,
}

impl Kernel for DiffusionKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, KERNEL, WGSL),
            uniforms: uniform_buffer(
                device,
                "diffusion uniforms",
                std::mem::size_of::<DiffusionUniforms>(),
            ),
            graph: None,
            scratch: None,
            bind_groups: None,
            coast_count: 0,
        }
    }
    fn forget_bind_groups(&mut self) {
        self.bind_groups = None;
    }
}

fn fail(message: String) -> GpuError {
    GpuError::Kernel {
        kernel: KERNEL,
        message,
    }
}

/// What identifies a graph: samples, edges and a hash of about 1,000 entries of each array,
/// spread evenly (a graph is made once per mesh; hashing all of it every call would cost
/// milliseconds at 500k samples).
fn graph_key(g: &DiffusionGraph) -> (usize, usize, u64) {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut mix = |x: u64| {
        h ^= x;
        h = h.wrapping_mul(0x0100_0000_01b3).rotate_left(17);
    };
    let stride = |len: usize| (len / 1024).max(1);
    let s = stride(g.neighbor_start.len());
    g.neighbor_start
        .iter()
        .step_by(s)
        .for_each(|&x| mix(x as u64));
    let s = stride(g.neighbors.len());
    g.neighbors.iter().step_by(s).for_each(|&x| mix(x as u64));
    g.edge_weight
        .iter()
        .step_by(s)
        .for_each(|&x| mix(x.to_bits() as u64));
    let s = stride(g.area_km2.len());
    g.area_km2.iter().step_by(s).for_each(|&x| mix(x.to_bits()));
    (g.len(), g.neighbors.len(), h)
}

/// Diffuses the resident elevation buffer in place (call [`GpuContext::sync_crust`] first, and
/// upload the elevation to diffuse into it): `steps.substeps` explicit sub-steps on the land
/// (samples not in `ocean`), the coast held at sea level; the outflow into each sample of
/// `coast` (the ocean samples with a land neighbour, any order) accumulates in its receipt.
/// Ocean samples and land samples whose elevation is not finite keep their elevation. Read the
/// result with [`diffusion_read_back`].
pub fn diffusion_dispatch(
    ctx: &mut GpuContext,
    graph: &DiffusionGraph,
    ocean: &[bool],
    coast: &[u32],
    steps: &DiffusionSteps,
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut DiffusionKernel| {
        let Some(n) = ctx.crust_buffers().map(|b| b.len) else {
            return Err(fail("the crust is not on the device".into()));
        };
        let m = graph.neighbors.len();
        if graph.len() != n
            || ocean.len() != n
            || graph.neighbor_start.len() != n + 1
            || graph.edge_weight.len() != m
            || graph
                .neighbor_start
                .last()
                .is_some_and(|&e| e as usize != m)
        {
            return Err(fail(format!(
                "a graph of {} samples and {m} edges ({} offsets, {} weights) and {} ocean \
                 flags for a crust of {n} samples",
                graph.len(),
                graph.neighbor_start.len(),
                graph.edge_weight.len(),
                ocean.len()
            )));
        }
        if let Some(&bad) = graph.neighbors.iter().find(|&&j| j as usize >= n) {
            return Err(fail(format!("neighbour {bad} of a graph of {n} samples")));
        }
        if let Some(&bad) = coast.iter().find(|&&j| j as usize >= n) {
            return Err(fail(format!(
                "coast sample {bad} of a graph of {n} samples"
            )));
        }
        if coast.len() > n {
            return Err(fail(format!("{} coast samples of {n}", coast.len())));
        }
        if n == 0 {
            return Ok(());
        }
        let key = graph_key(graph);
        if k.graph.as_ref().is_none_or(|g| g.key != key) {
            let mut nodes = Vec::with_capacity(2 * (n + 1));
            for i in 0..=n {
                let area = graph.area_km2.get(i).map_or(0.0, |&a| a as f32);
                nodes.extend([graph.neighbor_start[i], area.to_bits()]);
            }
            let edges: Vec<u32> = graph
                .neighbors
                .iter()
                .zip(graph.edge_weight)
                .flat_map(|(&j, &w)| [j, w.to_bits()])
                .collect();
            let nb = ctx.storage_buffer("diffusion nodes", 4 * nodes.len());
            let eb = ctx.storage_buffer("diffusion edges", 4 * edges.len());
            ctx.upload(&nb, bytemuck::cast_slice(&nodes));
            ctx.upload(&eb, bytemuck::cast_slice(&edges));
            k.graph = Some(GraphBuffers {
                nodes: nb,
                edges: eb,
                key,
            });
            k.bind_groups = None;
        }
        if k.scratch.as_ref().is_none_or(|s| s.len != n) {
            k.scratch = Some(Scratch {
                ocean: ctx.storage_buffer("diffusion ocean bits", 4 * n.div_ceil(32)),
                h_a: ctx.storage_buffer("diffusion h a", 4 * n),
                h_b: ctx.storage_buffer("diffusion h b", 4 * n),
                coast: ctx.storage_buffer("diffusion coast", 4 * n),
                receipts: ctx.storage_buffer("diffusion receipts", 4 * n),
                len: n,
            });
            k.bind_groups = None;
        }
        if k.bind_groups.is_none() {
            let (Some(b), Some(g), Some(s)) =
                (ctx.crust_buffers(), k.graph.as_ref(), k.scratch.as_ref())
            else {
                return Err(fail("buffers missing".into()));
            };
            let layout = k.pipeline.get_bind_group_layout(0);
            let group = |h_in: &wgpu::Buffer, h_out: &wgpu::Buffer| {
                ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("diffusion bindings"),
                    layout: &layout,
                    entries: &[
                        entry(0, &k.uniforms),
                        entry(1, &g.nodes),
                        entry(2, &g.edges),
                        entry(3, &s.ocean),
                        entry(4, &b.elevation_km),
                        entry(5, h_in),
                        entry(6, h_out),
                        entry(7, &s.coast),
                        entry(8, &s.receipts),
                    ],
                })
            };
            k.bind_groups = Some([group(&s.h_a, &s.h_b), group(&s.h_b, &s.h_a)]);
        }
        let (Some(s), Some([a_to_b, b_to_a])) = (k.scratch.as_ref(), k.bind_groups.clone()) else {
            return Err(fail("buffers missing".into()));
        };
        let (ocean_buf, coast_buf) = (s.ocean.clone(), s.coast.clone());
        let mut bits = vec![0u32; n.div_ceil(32)];
        for (i, _) in ocean.iter().enumerate().filter(|(_, o)| **o) {
            bits[i >> 5] |= 1 << (i & 31);
        }
        ctx.upload(&ocean_buf, bytemuck::cast_slice(&bits));
        ctx.upload(&coast_buf, bytemuck::cast_slice(coast));
        k.coast_count = coast.len();
        let threads = (n + coast.len()) as u32;
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        let phase = |ctx: &mut GpuContext, phase: u32, bg: &wgpu::BindGroup| {
            let u = DiffusionUniforms {
                rate: steps.rate_km2 as f32,
                count: n as u32,
                coast_count: coast.len() as u32,
                phase,
                row_stride: ROW_STRIDE,
                _pad: [0; 3],
            };
            ctx.upload(&uniforms, bytemuck::bytes_of(&u));
            ctx.dispatch(KERNEL, &pipeline, bg, threads)
        };
        // Start: h_a ← elevation (written through the group whose output is h_a).
        phase(ctx, 0, &b_to_a)?;
        for s in 0..steps.substeps {
            phase(ctx, 1, if s % 2 == 0 { &a_to_b } else { &b_to_a })?;
        }
        // The result is in h_a after an even number of sub-steps, else in h_b.
        let last = if steps.substeps.is_multiple_of(2) {
            &a_to_b
        } else {
            &b_to_a
        };
        phase(ctx, 2, last)?;
        ctx.traffic.diffusion_passes += 1;
        Ok(())
    })
}

/// Reads the diffused elevation (the resident elevation buffer, every sample) into
/// `elevation_km` and the receipts of the last [`diffusion_dispatch`]'s coast samples (km³, in
/// the order of its `coast`) into `receipts_km3`.
pub fn diffusion_read_back(
    ctx: &mut GpuContext,
    elevation_km: &mut [f32],
    receipts_km3: &mut [f32],
) -> Result<(), GpuError> {
    ctx.with_kernel(|ctx, k: &mut DiffusionKernel| {
        let Some(z) = ctx.crust_buffers().map(|b| b.elevation_km.clone()) else {
            return Err(fail("the crust is not on the device".into()));
        };
        let n = ctx.crust_buffers().map_or(0, |b| b.len);
        if elevation_km.len() != n || receipts_km3.len() != k.coast_count {
            return Err(fail(format!(
                "read back {} elevations and {} receipts of {n} samples and {} coast samples",
                elevation_km.len(),
                receipts_km3.len(),
                k.coast_count
            )));
        }
        let Some(r) = k.scratch.as_ref().map(|s| s.receipts.clone()) else {
            return Err(fail("no diffusion ran".into()));
        };
        ctx.download(KERNEL, &z, bytemuck::cast_slice_mut(elevation_km))?;
        ctx.download(KERNEL, &r, bytemuck::cast_slice_mut(receipts_km3))
    })
}
