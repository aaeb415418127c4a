//! Host side of `shaders/resample_locate.wgsl`: the point location of a global resampling (for
//! every reference sample, the covering plate after the plates moved, the triangle in that
//! plate's frame, the barycentric weights, the suture and the lost-continent flag; gaps are the
//! samples no plate covers). The CPU reference is [`resample_locate_cpu`](crate::systems::resample::resample_locate_cpu), the function the CPU
//! backend runs (`src/systems/resample/locate.rs`); the interpolation of the crust fields from the
//! located sources, the gap search and the rebuild stay on the CPU on both backends.
//!
//! What crosses the bus:
//! - **Once per run** (per mesh): the reference positions as f32 (12 bytes a sample), the
//!   triangles (12 bytes a triangle, about 24 bytes a sample) and the cube-map locator's cells
//!   (cell starts and triangle lists, about 20 bytes a sample).
//! - **Per resampling:** the plate table in rank order (rotation plate ← world, cap centroid and
//!   radius, id, slot: 64 bytes a plate), the override pairs, the suture targets, the locator
//!   cells' plate lists (8 bytes a cell) and, when sutures are pending, the suture of every old
//!   sample (4 bytes a sample). The old crust's plate ids and crust types are the resident
//!   crust buffers ([`crate::gpu::CrustBuffers`]). Read back: 32 bytes a sample (the CPU needs
//!   every source: gaps, sutures, lost continents). The output also stays on the device, and
//!   the sources the host rechecks are written into it ([`crate::gpu::sources_patch`], 36 bytes
//!   each), so the interpolation reads the sources there
//!   ([`crate::gpu::resample_interpolate::resample_interpolate_gpu_located`]).
//!
//! Precision: the GPU works in f32, the CPU in f64. Where f32 rounding could change a decision
//! (near a triangle edge or vertex, a tie of corners, a continental weight near 1/2, a locator
//! cell boundary, a cap rim), the kernel flags the sample and the host locates it again with
//! [`locate_one`](crate::systems::resample::locate_one), the CPU code. All other samples get the CPU's plate, slot, suture, flags and
//! triangle exactly, and weights within about 1e-5 of the CPU's.

use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::SphereMesh;
use crate::gpu::{
    GpuContext, GpuError, Kernel, ROW_STRIDE, compute_pipeline, entry, uniform_buffer,
};
use crate::resources::{Crust, NO_PLATE, PlateTable};

/// The kernel's WGSL.
pub const WGSL: &str = include_str!("../../shaders/resample_locate.wgsl");

/// Up to four plate slots per locator cell: the plates owning a vertex of a triangle that
/// touches the cell ([`CellPlates::MANY`] in the first entry when there are more). A plate absent
/// from the cell of a point cannot cover the point, so most plates are rejected without locating.
pub struct CellPlates {
    cells: Vec<[u16; 4]>,
}

impl CellPlates {
    const EMPTY: u16 = u16::MAX;
    /// First entry of a cell touched by more plates than the entry holds.
    pub const MANY: u16 = u16::MAX - 1;

    /// Builds the lists for the ownership of `old` (slots of `table`).
    pub fn build(mesh: &SphereMesh, old: &Crust, table: &PlateTable) -> Self {
        let slot_of_sample: Vec<u16> = old
            .plate
            .par_iter()
            .with_min_len(4096)
            .map(|&p| {
                table
                    .slot(p)
                    .map_or(Self::EMPTY, |s| s.min(Self::MANY as usize - 1) as u16)
            })
            .collect();
        let loc = mesh.locator();
        let mut cells = vec![[Self::EMPTY; 4]; loc.cell_count()];
        if table.len() >= Self::MANY as usize {
            cells.fill([Self::MANY, Self::EMPTY, Self::EMPTY, Self::EMPTY]);
            return Self { cells };
        }
        // Each triangle's slot when its three vertices share it (most triangles: a cell then
        // reads one value per triangle instead of three), `MIXED` otherwise. Slots here are
        // below `MIXED`.
        const MIXED: u16 = CellPlates::MANY - 1;
        let tri_slot: Vec<u16> = mesh
            .triangles
            .par_iter()
            .with_min_len(4096)
            .map(|t| {
                let s = slot_of_sample[t[0] as usize];
                if slot_of_sample[t[1] as usize] == s && slot_of_sample[t[2] as usize] == s {
                    s
                } else {
                    MIXED
                }
            })
            .collect();
        cells
            .par_iter_mut()
            .enumerate()
            .with_min_len(1024)
            .for_each(|(c, list)| {
                let mut n = 0;
                // The slots of a cell's triangles' vertices in order, each listed once.
                let mut add = |list: &mut [u16; 4], s: u16| -> bool {
                    if s == Self::EMPTY || list[..n].contains(&s) {
                        return true;
                    }
                    if n == 4 {
                        *list = [Self::MANY, Self::EMPTY, Self::EMPTY, Self::EMPTY];
                        return false;
                    }
                    list[n] = s;
                    n += 1;
                    true
                };
                for &t in loc.cell_triangles(c) {
                    let ts = tri_slot[t as usize];
                    let more = if ts != MIXED {
                        add(list, ts)
                    } else {
                        mesh.triangles[t as usize]
                            .iter()
                            .all(|&v| add(list, slot_of_sample[v as usize]))
                    };
                    if !more {
                        return;
                    }
                }
            });
        Self { cells }
    }

    /// The lists, one `[u16; 4]` per locator cell (what the GPU kernel reads).
    pub fn lists(&self) -> &[[u16; 4]] {
        &self.cells
    }

    /// Whether plate `slot` may cover points of cell `c`.
    #[inline]
    pub fn may_cover(&self, c: usize, slot: u32) -> bool {
        let l = &self.cells[c];
        l[0] == Self::MANY || l.contains(&(slot as u16))
    }
}

/// Where one output sample takes its data from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleSource {
    /// Slot (in the plate table) of the covering plate, `u32::MAX` for a gap.
    pub slot: u32,
    /// The plate the sample belongs to after the resampling: the covering plate, or the plate a
    /// colliding terrane sutures to.
    pub plate: u32,
    /// Index of the pending suture that moved this sample, `u32::MAX` if none.
    pub suture: u32,
    /// True when another plate's continental crust covered this sample too and went under.
    pub continental_lost: bool,
    /// Triangle of the reference mesh, in the plate frame.
    pub triangle: u32,
    /// Barycentric weights in that triangle (f32 is plenty for interpolating f32 fields, and a
    /// weight of exactly 1 stays exactly 1).
    pub weights: [f32; 3],
}

impl SampleSource {
    pub(crate) const GAP: SampleSource = SampleSource {
        slot: u32::MAX,
        plate: NO_PLATE,
        suture: u32::MAX,
        continental_lost: false,
        triangle: 0,
        weights: [0.0; 3],
    };
    /// True when no plate covers the sample.
    pub fn is_gap(&self) -> bool {
        self.slot == u32::MAX
    }
}

/// What decides between two plates that both cover a sample from their core (an overlap).
#[derive(Clone, Copy, Debug, Default)]
pub struct OverlapRules<'a> {
    /// (overriding, subducting) plate pairs of the subduction fronts, sorted.
    pub pairs: &'a [(u32, u32)],
    /// Per reference sample of the old crust: the index of the pending suture that moves it
    /// (`u32::MAX` if none).
    pub suture_of_sample: &'a [u32],
    /// Target plate of each pending suture.
    pub suture_target: &'a [u32],
}

/// Flag of the kernel's output: another plate's continental crust went under here.
const FLAG_CONTINENTAL_LOST: u32 = 1;
/// Flag of the kernel's output: the host must locate this sample again in f64.
const FLAG_DOUBT: u32 = 2;

/// Uniforms of one location pass. Keep in sync with `LocateUniforms` in
/// shaders/resample_locate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct LocateUniforms {
    /// Samples.
    pub count: u32,
    /// Threads per dispatch row.
    pub row_stride: u32,
    /// Plates.
    pub plate_count: u32,
    /// Override pairs.
    pub pair_count: u32,
    /// Entries of the per-sample suture buffer (0 when no suture is pending).
    pub suture_len: u32,
    /// Locator cells along a face edge.
    pub grid: u32,
    /// Locator cells.
    pub cell_count: u32,
    /// Word offset of the override pairs in the auxiliary buffer.
    pub pairs_at: u32,
    /// Word offset of the suture targets in the auxiliary buffer.
    pub targets_at: u32,
    /// Word offset of the cell plate lists in the auxiliary buffer.
    pub cells_at: u32,
    /// Barycentric margin under which a decision is left to the CPU.
    pub doubt_w: f32,
    /// Margin (in cells) around locator cell boundaries left to the CPU.
    pub doubt_cell: f32,
}

/// One plate as the kernel reads it (16 words). Keep in sync with `PLATE_WORDS` and the reads
/// in shaders/resample_locate.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuPlate {
    /// Rows of the rotation plate ← world, each followed by one coordinate of the cap centroid
    /// (world frame): `[r0.x, r0.y, r0.z, c.x, r1.x, …, c.z]`.
    pub rows_centroid: [f32; 12],
    /// Cosine of the cap radius.
    pub cap_cos: f32,
    /// Plate id.
    pub id: u32,
    /// Slot in the plate table.
    pub slot: u32,
    /// Padding.
    pub _pad: u32,
}

/// The mesh on the device (uploaded once per mesh).
struct MeshBuffers {
    key: (usize, usize, usize),
    positions: wgpu::Buffer,
    triangles: wgpu::Buffer,
    cells: wgpu::Buffer,
    cell_count: u32,
    grid: u32,
}

/// Pipeline, uniforms and the resident mesh.
pub(crate) struct LocateKernel {
    pipeline: wgpu::ComputePipeline,
    uniforms: wgpu::Buffer,
    mesh: Option<MeshBuffers>,
    /// The last location's output on the device (8 words a sample) and its sample count.
    located: Option<(wgpu::Buffer, usize)>,
    /// True when `located` holds, for every sample, the source [`resample_locate_gpu`]
    /// returned (the rechecked samples written back): the interpolation may read it there.
    located_complete: bool,
}

impl Kernel for LocateKernel {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            pipeline: compute_pipeline(device, "resample_locate", WGSL),
            uniforms: uniform_buffer(
                device,
                "resample_locate uniforms",
                std::mem::size_of::<LocateUniforms>(),
            ),
            mesh: None,
            located: None,
            located_complete: false,
        }
    }
}

impl LocateKernel {
    /// The last location's output on the device when it is complete (see `located_complete`)
    /// and has `n` samples.
    pub(crate) fn located_output(&self, n: usize) -> Option<wgpu::Buffer> {
        self.located
            .as_ref()
            .filter(|(_, len)| self.located_complete && *len == n)
            .map(|(b, _)| b.clone())
    }
}

/// What a GPU location did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LocateReport {
    /// Samples whose decision the kernel left to the CPU (located again with [`locate_one`](crate::systems::resample::locate_one)).
    pub rechecked: usize,
    /// Samples no plate covers (gaps).
    pub gaps: usize,
}

/// The barycentric margin under which the kernel leaves a decision to the CPU, for a mesh of
/// mean spacing `spacing_rad`. The f32 rounding of positions and rotations (~1e-7) over the
/// triangle size (~the spacing) bounds the error of f32 weights; the margin is about 20 times
/// that, and at least 1e-4.
pub fn doubt_margin(spacing_rad: f64) -> f32 {
    (2e-6 / spacing_rad.max(1e-9)).clamp(1e-4, 0.05) as f32
}

fn too_large(what: &str, bytes: usize, limit: u64) -> Result<(), GpuError> {
    if bytes as u64 > limit {
        return Err(GpuError::TooLarge(format!(
            "resample_locate: {what} needs {bytes} bytes, more than the device's storage binding \
             limit of {limit} bytes"
        )));
    }
    Ok(())
}

fn ensure_mesh(
    ctx: &mut GpuContext,
    k: &mut LocateKernel,
    mesh: &SphereMesh,
) -> Result<(), GpuError> {
    let loc = mesh.locator();
    let key = (mesh.len(), mesh.triangles.len(), loc.cell_count());
    if k.mesh.as_ref().is_some_and(|m| m.key == key) {
        return Ok(());
    }
    k.mesh = None;
    let limit = ctx.device.limits().max_storage_buffer_binding_size;
    let positions: Vec<f32> = mesh
        .positions
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    let triangles: &[u32] = bytemuck::cast_slice(&mesh.triangles);
    let mut cells: Vec<u32> =
        Vec::with_capacity(loc.cell_starts().len() + loc.cell_triangle_list().len());
    cells.extend_from_slice(loc.cell_starts());
    cells.extend_from_slice(loc.cell_triangle_list());
    too_large("the positions", 4 * positions.len(), limit)?;
    too_large("the triangles", 4 * triangles.len(), limit)?;
    too_large("the locator cells", 4 * cells.len(), limit)?;
    let b = MeshBuffers {
        key,
        positions: ctx.storage_buffer("locate positions", 4 * positions.len()),
        triangles: ctx.storage_buffer("locate triangles", 4 * triangles.len()),
        cells: ctx.storage_buffer("locate cells", 4 * cells.len()),
        cell_count: loc.cell_count() as u32,
        grid: loc.grid() as u32,
    };
    ctx.upload(&b.positions, bytemuck::cast_slice(&positions));
    ctx.upload(&b.triangles, bytemuck::cast_slice(triangles));
    ctx.upload(&b.cells, bytemuck::cast_slice(&cells));
    ctx.check("resample_locate mesh upload")?;
    k.mesh = Some(b);
    Ok(())
}

fn plate_words(table: &PlateTable) -> Vec<GpuPlate> {
    table
        .by_rank
        .iter()
        .map(|&slot| {
            let p = &table.plates[slot as usize];
            let m = p.plate_from_world;
            let row = |i: usize| DVec3::new(m.x_axis[i], m.y_axis[i], m.z_axis[i]);
            let (r0, r1, r2, c) = (row(0), row(1), row(2), p.centroid_world);
            GpuPlate {
                rows_centroid: [
                    r0.x, r0.y, r0.z, c.x, r1.x, r1.y, r1.z, c.y, r2.x, r2.y, r2.z, c.z,
                ]
                .map(|x| x as f32),
                cap_cos: p.cap_cos as f32,
                id: p.id,
                slot,
                _pad: 0,
            }
        })
        .collect()
}

/// Runs the kernel and reads its output back: per sample, the source as the kernel found it
/// (gaps as [`SampleSource`] gaps), and the samples the kernel left to the CPU (their sources
/// are gaps here). [`resample_locate_gpu`](crate::systems::resample::resample_locate_gpu) then locates those on the CPU. The kernel reads the
/// old crust's plates and crust types from the resident buffers: call
/// [`GpuContext::sync_crust`] with `old` first (`old` itself only sizes the check here).
pub fn resample_locate_raw(
    ctx: &mut GpuContext,
    mesh: &SphereMesh,
    old: &Crust,
    table: &PlateTable,
    rules: &OverlapRules,
    cell_plates: &CellPlates,
) -> Result<(Vec<SampleSource>, Vec<u32>), GpuError> {
    ctx.with_kernel(|ctx, k: &mut LocateKernel| {
        let n = mesh.len();
        if old.len() != n || cell_plates.lists().len() != mesh.locator().cell_count() {
            return Err(GpuError::Kernel {
                kernel: "resample_locate",
                message: format!(
                    "inputs of different sizes: mesh {n}, crust {}, cell lists {}",
                    old.len(),
                    cell_plates.lists().len()
                ),
            });
        }
        if rules.suture_of_sample.len() > n {
            return Err(GpuError::Kernel {
                kernel: "resample_locate",
                message: "more sutured samples than samples".into(),
            });
        }
        k.located_complete = false;
        ensure_mesh(ctx, k, mesh)?;
        // The auxiliary buffer: plates, pairs, suture targets, cell lists.
        let plates = plate_words(table);
        let mut aux: Vec<u32> = bytemuck::cast_slice(&plates).to_vec();
        let pairs_at = aux.len() as u32;
        for &(a, b) in rules.pairs {
            aux.extend_from_slice(&[a, b]);
        }
        let targets_at = aux.len() as u32;
        aux.extend_from_slice(rules.suture_target);
        let cells_at = aux.len() as u32;
        aux.extend_from_slice(bytemuck::cast_slice(cell_plates.lists()));
        let limit = ctx.device.limits().max_storage_buffer_binding_size;
        too_large("the plate table and cell lists", 4 * aux.len(), limit)?;
        too_large("the output", 32 * n, limit)?;
        // The old crust's plates and crust types are the resident buffers (stage 3 of
        // docs/gpu-residency.md): nothing of the crust goes up here.
        let Some((plate_buf, type_buf)) = ctx
            .crust_buffers()
            .filter(|b| b.len == n)
            .map(|b| (b.plate.clone(), b.crust_type.clone()))
        else {
            return Err(GpuError::Kernel {
                kernel: "resample_locate",
                message: "the old crust is not on the device (call sync_crust first)".into(),
            });
        };
        let aux_buf = ctx.storage_buffer("locate aux", 4 * aux.len());
        ctx.upload(&aux_buf, bytemuck::cast_slice(&aux));
        let suture_buf = ctx.storage_buffer("locate sutures", 4 * rules.suture_of_sample.len());
        ctx.upload(&suture_buf, bytemuck::cast_slice(rules.suture_of_sample));
        // The output stays on the device for the interpolation (one buffer per mesh size).
        if k.located.as_ref().is_none_or(|(_, len)| *len != n) {
            let buf = ctx.storage_buffer("locate output", 32 * n);
            k.located = Some((buf, n));
        }
        let Some(out_buf) = k.located.as_ref().map(|(b, _)| b.clone()) else {
            return Err(GpuError::Kernel {
                kernel: "resample_locate",
                message: "no output buffer".into(),
            });
        };
        let Some(m) = k.mesh.as_ref() else {
            return Err(GpuError::Kernel {
                kernel: "resample_locate",
                message: "the mesh is not on the device".into(),
            });
        };
        let u = LocateUniforms {
            count: n as u32,
            row_stride: ROW_STRIDE,
            plate_count: plates.len() as u32,
            pair_count: rules.pairs.len() as u32,
            suture_len: rules.suture_of_sample.len() as u32,
            grid: m.grid,
            cell_count: m.cell_count,
            pairs_at,
            targets_at,
            cells_at,
            doubt_w: doubt_margin(mesh.mean_spacing_rad()),
            doubt_cell: 1e-3,
        };
        let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("resample_locate bindings"),
            layout: &k.pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &k.uniforms),
                entry(1, &m.positions),
                entry(2, &m.triangles),
                entry(3, &m.cells),
                entry(4, &aux_buf),
                entry(5, &plate_buf),
                entry(6, &type_buf),
                entry(7, &suture_buf),
                entry(8, &out_buf),
            ],
        });
        let (pipeline, uniforms) = (k.pipeline.clone(), k.uniforms.clone());
        ctx.upload(&uniforms, bytemuck::bytes_of(&u));
        ctx.dispatch("resample_locate", &pipeline, &bind_group, n as u32)?;
        let mut words = vec![[u32::MAX; 8]; n];
        ctx.download(
            "resample_locate",
            &out_buf,
            bytemuck::cast_slice_mut(&mut words),
        )?;
        let doubtful: Vec<u32> = words
            .iter()
            .enumerate()
            .filter(|(_, w)| w[3] & FLAG_DOUBT != 0)
            .map(|(j, _)| j as u32)
            .collect();
        let sources = words
            .par_iter()
            .with_min_len(4096)
            .map(|w| {
                if w[0] == u32::MAX {
                    SampleSource {
                        slot: u32::MAX,
                        plate: NO_PLATE,
                        suture: u32::MAX,
                        continental_lost: false,
                        triangle: 0,
                        weights: [0.0; 3],
                    }
                } else {
                    SampleSource {
                        slot: w[0],
                        plate: w[1],
                        suture: w[2],
                        continental_lost: w[3] & FLAG_CONTINENTAL_LOST != 0,
                        triangle: w[4],
                        weights: [
                            f32::from_bits(w[5]),
                            f32::from_bits(w[6]),
                            f32::from_bits(w[7]),
                        ],
                    }
                }
            })
            .collect();
        Ok((sources, doubtful))
    })
}

/// The buffer holding the last location's output on the device (8 words a sample) and its
/// sample count, if a location ran.
pub fn located_buffer(ctx: &mut GpuContext) -> Option<(wgpu::Buffer, usize)> {
    ctx.with_kernel(|_, k: &mut LocateKernel| k.located.clone())
}

/// Records that the last location's output on the device now holds, for every sample, the
/// source the host settled on (the rechecked samples patched in with
/// [`crate::gpu::sources_patch`]), so the interpolation may read the sources there.
pub fn mark_located_complete(ctx: &mut GpuContext) {
    ctx.with_kernel(|_, k: &mut LocateKernel| k.located_complete = true);
}

/// The last location's output on the device when it is complete (see
/// [`mark_located_complete`]) and has `n` samples.
pub fn located_output(ctx: &mut GpuContext, n: usize) -> Option<wgpu::Buffer> {
    ctx.with_kernel(|_, k: &mut LocateKernel| k.located_output(n))
}
