//! Host side of `shaders/crust_reduce.wgsl`: what the diagnostics need from the resident crust,
//! reduced on the device, so a step reads back N/8 bytes (a land bitmask) instead of the
//! elevation: the land bitmask (elevation > 0, one bit a sample), the elevation min and max
//! (NaN skipped, as `f32::min`/`max` do) and the first non-finite index of each device-written
//! scalar field. The CPU reference is [`crust_reduce_cpu`]; both are exact (bit tests, and
//! min/max/first index do not depend on the order).
//!
//! [`stats_from_reduction`] then sums the land area in f64 in the chunk order of
//! [`crust_stats`](crate::systems::diagnostics::crust_stats), so the stats are bit-identical to
//! the CPU path (up to the sign of a zero elevation extreme, which `f32::min` leaves open and
//! `==` ignores).

use rayon::prelude::*;

use crate::geometry::SphereMesh;
use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};
use crate::resources::{CrustStats, CrustType};

/// Chunk size of deterministic reductions.
pub const REDUCE_CHUNK: usize = 8192;

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/crust_reduce.wgsl");

/// Header words before the mask in the output buffer (`OUT_HEADER` in the WGSL).
pub const HEADER_WORDS: usize = 6;
/// "No non-finite sample" in the output (`NO_INDEX` in the WGSL).
pub const NO_INDEX: u32 = u32::MAX;

/// Uniforms of one reduction. Keep in sync with `ReduceUniforms` in shaders/crust_reduce.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ReduceUniforms {
    /// Samples.
    pub count: u32,
    /// Mask words (threads): ceil(count / 32).
    pub words: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}

/// The reduction of one crust.
#[derive(Clone, Debug, PartialEq)]
pub struct CrustReduction {
    /// Bit j of word w: sample 32w + j has elevation > 0.
    pub land_mask: Vec<u32>,
    /// Smallest elevation (NaN skipped; +inf when there is none).
    pub min_elevation_km: f32,
    /// Largest elevation (NaN skipped; −inf when there is none).
    pub max_elevation_km: f32,
    /// First non-finite sample of elevation, age, orogeny age and fold direction.
    pub first_non_finite: [Option<usize>; 4],
}

/// Field names of [`CrustReduction::first_non_finite`], as `Crust::check_finite` names them.
pub const FIELDS: [&str; 4] = ["elevation_km", "age_my", "orogeny_age_my", "fold_dir"];

/// CPU reference of the kernel.
pub fn crust_reduce_cpu(
    elevation_km: &[f32],
    age_my: &[f32],
    orogeny_age_my: &[f32],
    fold_dir: &[[f32; 3]],
) -> CrustReduction {
    let mut land_mask = vec![0u32; elevation_km.len().div_ceil(32)];
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (i, &z) in elevation_km.iter().enumerate() {
        if z > 0.0 {
            land_mask[i / 32] |= 1 << (i % 32);
        }
        lo = lo.min(z);
        hi = hi.max(z);
    }
    let first = |v: &[f32]| v.iter().position(|x| !x.is_finite());
    CrustReduction {
        land_mask,
        min_elevation_km: lo,
        max_elevation_km: hi,
        first_non_finite: [
            first(elevation_km),
            first(age_my),
            first(orogeny_age_my),
            fold_dir
                .iter()
                .position(|x| !x.iter().all(|c| c.is_finite())),
        ],
    }
}

/// Land and continental fractions and the elevation range from a reduction, the crust types and
/// the mesh areas: the f64 sums of `crust_stats` in its chunk order (plates left at 0).
pub fn stats_from_reduction(
    mesh: &SphereMesh,
    crust_type: &[CrustType],
    r: &CrustReduction,
) -> CrustStats {
    let mask = &r.land_mask;
    let partial: Vec<(f64, f64, f64)> = crust_type
        .par_chunks(REDUCE_CHUNK)
        .zip(mesh.area_km2.par_chunks(REDUCE_CHUNK))
        .enumerate()
        .map(|(c, (t, a))| {
            let base = c * REDUCE_CHUNK;
            let (mut total, mut land, mut cont) = (0.0, 0.0, 0.0);
            for k in 0..t.len() {
                let i = base + k;
                total += a[k];
                if mask[i / 32] >> (i % 32) & 1 == 1 {
                    land += a[k];
                }
                if t[k] == CrustType::Continental {
                    cont += a[k];
                }
            }
            (total, land, cont)
        })
        .collect();
    let (mut total, mut land, mut cont) = (0.0, 0.0, 0.0);
    for (t, l, c) in partial {
        total += t;
        land += l;
        cont += c;
    }
    CrustStats {
        land_fraction: land / total.max(f64::MIN_POSITIVE),
        continental_fraction: cont / total.max(f64::MIN_POSITIVE),
        plates: 0,
        elevation_range_km: (r.min_elevation_km, r.max_elevation_km),
    }
}

/// Pipeline, uniforms and the output buffer (grown on demand).
pub(crate) struct ReduceKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    output: Option<(usize, wgpu::Buffer)>,
    bind_group: Option<wgpu::BindGroup>,
}

impl Kernel for ReduceKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, "crust_reduce", WGSL),
            uniforms: uniform_buffer(
                device,
                "crust_reduce uniforms",
                std::mem::size_of::<ReduceUniforms>(),
            ),
            output: None,
            bind_group: None,
        }
    }
    fn forget_bind_groups(&mut self) {
        self.bind_group = None;
    }
}

fn from_ordered(u: u32) -> f32 {
    f32::from_bits(if u & 0x8000_0000 != 0 {
        u & 0x7fff_ffff
    } else {
        !u
    })
}

fn to_ordered(x: f32) -> u32 {
    let b = x.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// Runs the reduction on the resident crust (call [`GpuContext::sync_crust`] first); reads back
/// 24 bytes plus one word per 32 samples.
pub fn crust_reduce_gpu(ctx: &mut GpuContext) -> Result<CrustReduction, GpuError> {
    ctx.with_kernel(|ctx, k: &mut ReduceKernel| {
        const KERNEL: &str = "crust_reduce";
        let Some(b) = ctx.crust_buffers() else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "the crust is not on the device".into(),
            });
        };
        let n = b.len;
        let bufs = [
            b.elevation_km.clone(),
            b.age_my.clone(),
            b.orogeny_age_my.clone(),
            b.fold_dir.clone(),
        ];
        let words = n.div_ceil(32);
        let len = HEADER_WORDS + words;
        if k.output.as_ref().is_none_or(|(cap, _)| *cap != len) {
            let out = ctx.storage_buffer("crust_reduce output", 4 * len);
            k.output = Some((len, out));
            k.bind_group = None;
        }
        let Some((_, out)) = k.output.clone() else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "no output buffer".into(),
            });
        };
        if k.bind_group.is_none() {
            let bg = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("crust_reduce bindings"),
                layout: &k.pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &k.uniforms),
                    entry(1, &bufs[0]),
                    entry(2, &bufs[1]),
                    entry(3, &bufs[2]),
                    entry(4, &bufs[3]),
                    entry(5, &out),
                ],
            });
            k.bind_group = Some(bg);
        }
        let u = ReduceUniforms {
            count: n as u32,
            words: words as u32,
            row_stride: ROW_STRIDE,
            _pad: 0,
        };
        let header: [u32; HEADER_WORDS] = [
            to_ordered(f32::INFINITY),
            to_ordered(f32::NEG_INFINITY),
            NO_INDEX,
            NO_INDEX,
            NO_INDEX,
            NO_INDEX,
        ];
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        ctx.upload(&out, bytemuck::cast_slice(&header));
        let Some(bg) = k.bind_group.clone() else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "no bind group".into(),
            });
        };
        ctx.dispatch(KERNEL, &pipeline, &bg, words as u32)?;
        // Poisoned: a readback that copies nothing cannot pass for a result.
        let mut raw = vec![0xdead_beef_u32; len];
        ctx.download(KERNEL, &out, bytemuck::cast_slice_mut(&mut raw))?;
        let first = |w: u32| (w != NO_INDEX).then_some(w as usize);
        Ok(CrustReduction {
            min_elevation_km: from_ordered(raw[0]),
            max_elevation_km: from_ordered(raw[1]),
            first_non_finite: [first(raw[2]), first(raw[3]), first(raw[4]), first(raw[5])],
            land_mask: raw.split_off(HEADER_WORDS),
        })
    })
}
