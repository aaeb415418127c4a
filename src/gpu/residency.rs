//! The crust resident on the device: its buffers ([`CrustBuffers`]), which fields the device
//! holds newer than the host ([`FieldMask`]), and the uploads and pulls that keep the two in step
//! (see the module documentation of [`crate::gpu`] and docs/gpu-residency.md).

use bevy_ecs::change_detection::{DetectChangesMut, Tick};
use bevy_ecs::prelude::*;

use super::backend::GpuError;
use super::context::GpuContext;
use crate::resources::Crust;

/// A set of the resident crust fields (bits), used to record which ones the device holds newer
/// than the host [`Crust`] (the six fields kernels write, [`FieldMask::ALL`]) and which ones a
/// host writer declares ([`write_crust_fields`], any bit).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FieldMask(pub u16);

impl FieldMask {
    /// No field.
    pub const NONE: Self = Self(0);
    /// Elevation.
    pub const ELEVATION: Self = Self(1);
    /// Crust age.
    pub const AGE: Self = Self(2);
    /// Orogeny.
    pub const OROGENY: Self = Self(4);
    /// Orogeny age.
    pub const OROGENY_AGE: Self = Self(8);
    /// Fold direction.
    pub const FOLD_DIR: Self = Self(16);
    /// Crust thickness (the uplift kernels thicken the crust).
    pub const THICKNESS: Self = Self(32);
    /// Every field a kernel writes (crust type, ridge direction and plate are never written on
    /// the device).
    pub const ALL: Self = Self(63);
    /// Ridge direction (no kernel writes it).
    pub const RIDGE_DIR: Self = Self(64);
    /// Plate id (no kernel writes it).
    pub const PLATE: Self = Self(128);
    /// Crust type (no kernel writes it).
    pub const CRUST_TYPE: Self = Self(256);
    /// Every resident field.
    pub const EVERY_FIELD: Self = Self(511);
    /// True when no bit is set.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }
    /// True when every bit of `other` is set.
    pub fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }
    /// The bits set in both.
    pub fn and(self, other: Self) -> Self {
        Self(self.0 & other.0)
    }
}

impl std::ops::BitOr for FieldMask {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

impl std::ops::BitOrAssign for FieldMask {
    fn bitor_assign(&mut self, rhs: Self) {
        self.0 |= rhs.0;
    }
}

/// The crust fields resident on the device (see the module documentation).
pub struct CrustBuffers {
    /// Samples.
    pub len: usize,
    /// Elevation, f32 per sample, km.
    pub elevation_km: wgpu::Buffer,
    /// Crust type, u8 per sample packed four to a word.
    pub crust_type: wgpu::Buffer,
    /// Crust age, f32 per sample, My.
    pub age_my: wgpu::Buffer,
    /// Orogeny, u8 per sample packed four to a word.
    pub orogeny: wgpu::Buffer,
    /// Orogeny age, f32 per sample, My.
    pub orogeny_age_my: wgpu::Buffer,
    /// Fold direction, three f32 per sample, plate frame.
    pub fold_dir: wgpu::Buffer,
    /// Crust thickness, f32 per sample, km (the uplift kernels thicken it).
    pub thickness_km: wgpu::Buffer,
    /// Ridge direction, three f32 per sample, plate frame (no kernel writes it; the
    /// resampling reads it).
    pub ridge_dir: wgpu::Buffer,
    /// Plate id, u32 per sample (no kernel writes it; the resampling reads it).
    pub plate: wgpu::Buffer,
}

impl GpuContext {
    /// The resident crust buffers (after [`Self::sync_crust`]).
    pub fn crust_buffers(&self) -> Option<&CrustBuffers> {
        self.crust.as_ref()
    }

    /// Makes the resident buffers hold `crust`: allocates them for its size and uploads every
    /// field unless the device copy is already in sync with the host change tick `host_tick`
    /// (pass `None` to force the upload).
    ///
    /// Fails with [`GpuError::StaleHostWrite`] instead of uploading when the device holds fields
    /// newer than the host (see [`Self::device_newer`]): the host copy was written without a
    /// pull, and uploading it would lose the device's data.
    pub fn sync_crust(&mut self, crust: &Crust, host_tick: Option<Tick>) -> Result<(), GpuError> {
        let n = crust.len();
        if self.crust.as_ref().is_some_and(|b| b.len == n)
            && host_tick.is_some()
            && self.crust_synced == host_tick
        {
            return Ok(());
        }
        if !self.device_newer.is_empty() {
            return Err(GpuError::StaleHostWrite(self.device_newer));
        }
        if self.crust.as_ref().is_none_or(|b| b.len != n) {
            let b = CrustBuffers {
                len: n,
                elevation_km: self.storage_buffer("crust elevation_km", 4 * n),
                crust_type: self.storage_buffer("crust crust_type (u8 x4)", n),
                age_my: self.storage_buffer("crust age_my", 4 * n),
                orogeny: self.storage_buffer("crust orogeny (u8 x4)", n),
                orogeny_age_my: self.storage_buffer("crust orogeny_age_my", 4 * n),
                fold_dir: self.storage_buffer("crust fold_dir", 12 * n),
                thickness_km: self.storage_buffer("crust thickness_km", 4 * n),
                ridge_dir: self.storage_buffer("crust ridge_dir", 12 * n),
                plate: self.storage_buffer("crust plate", 4 * n),
            };
            self.crust = Some(b);
            self.forget_bind_groups();
        }
        let Some(b) = self.crust.take() else {
            return Err(GpuError::Kernel {
                kernel: "crust upload",
                message: "no crust buffers".into(),
            });
        };
        self.upload_fields(&b, crust, FieldMask::EVERY_FIELD);
        self.crust = Some(b);
        self.crust_synced = host_tick;
        self.traffic.crust_uploads += 1;
        self.check("crust upload")
    }

    /// Records that the device copy of the crust equals the host copy as of change tick `tick`.
    pub fn mark_crust_synced(&mut self, tick: Tick) {
        self.crust_synced = Some(tick);
    }

    /// Forgets the sync state, so the next kernel uploads the whole crust.
    pub fn invalidate_crust(&mut self) {
        self.crust_synced = None;
    }

    /// The resident fields the device holds newer than the host [`Crust`] (written by kernels
    /// since the last pull).
    pub fn device_newer(&self) -> FieldMask {
        self.device_newer
    }

    /// Records that a kernel wrote `fields` on the device; with [`Self::eager_sync`] pulls them
    /// into `crust` at once. Pass the crust through `bypass_change_detection` (a pull is not a
    /// host write).
    pub fn note_device_write(
        &mut self,
        fields: FieldMask,
        crust: &mut Crust,
    ) -> Result<(), GpuError> {
        self.device_newer |= fields;
        if self.eager_sync {
            self.pull(crust, FieldMask::ALL)?;
        }
        Ok(())
    }

    /// Uploads the fields of `fields` of `crust` whole into the resident buffers `b` (the full
    /// upload of [`Self::sync_crust`] and the declared one of [`Self::note_host_write`]).
    fn upload_fields(&mut self, b: &CrustBuffers, crust: &Crust, fields: FieldMask) {
        let has = |f: FieldMask| fields.and(f) == f;
        if has(FieldMask::ELEVATION) {
            self.upload(&b.elevation_km, bytemuck::cast_slice(&crust.elevation_km));
        }
        if has(FieldMask::AGE) {
            self.upload(&b.age_my, bytemuck::cast_slice(&crust.age_my));
        }
        if has(FieldMask::OROGENY) {
            self.upload(&b.orogeny, bytemuck::cast_slice(&crust.orogeny));
        }
        if has(FieldMask::OROGENY_AGE) {
            self.upload(
                &b.orogeny_age_my,
                bytemuck::cast_slice(&crust.orogeny_age_my),
            );
        }
        if has(FieldMask::FOLD_DIR) {
            self.upload(&b.fold_dir, bytemuck::cast_slice(&crust.fold_dir));
        }
        if has(FieldMask::THICKNESS) {
            self.upload(&b.thickness_km, bytemuck::cast_slice(&crust.thickness_km));
        }
        if has(FieldMask::RIDGE_DIR) {
            self.upload(&b.ridge_dir, bytemuck::cast_slice(&crust.ridge_dir));
        }
        if has(FieldMask::PLATE) {
            self.upload(&b.plate, bytemuck::cast_slice(&crust.plate));
        }
        if has(FieldMask::CRUST_TYPE) {
            self.upload(&b.crust_type, bytemuck::cast_slice(&crust.crust_type));
        }
    }

    /// Marks `fields` newer on the device (a kernel wrote them) and pulls them into `crust` at
    /// once (tests and the kernels' `read_back` helpers; the systems leave them on the device).
    pub fn pull_written(&mut self, fields: FieldMask, crust: &mut Crust) -> Result<(), GpuError> {
        self.device_newer |= fields;
        self.pull(crust, fields)
    }

    /// Whether a host write of `fields` into a crust of `len` samples whose change tick is
    /// `before` can be declared (see [`write_crust_fields`]): the device copy is in sync with
    /// the host as of `before` and holds none of `fields` newer.
    pub fn can_declare_host_write(&self, fields: FieldMask, len: usize, before: Tick) -> bool {
        self.crust_synced == Some(before)
            && self.crust.as_ref().is_some_and(|b| b.len == len)
            && self.device_newer.and(fields).is_empty()
    }

    /// After a declared host write (see [`Self::can_declare_host_write`]): uploads the fields of
    /// `fields` of `crust` whole and records the device in sync with the host change tick
    /// `after` (the tick the write moved the crust to). The other fields were not written, so
    /// the device's copies (newer or not) stay as they are.
    pub fn note_host_write(
        &mut self,
        crust: &Crust,
        fields: FieldMask,
        after: Tick,
    ) -> Result<(), GpuError> {
        let Some(b) = self.crust.take() else {
            return Err(GpuError::Kernel {
                kernel: "crust field upload",
                message: "no crust buffers".into(),
            });
        };
        if b.len != crust.len() || !self.device_newer.and(fields).is_empty() {
            let message = format!(
                "declared write of {fields:?}: host {} samples, device {}, device newer {:?}",
                crust.len(),
                b.len,
                self.device_newer
            );
            self.crust = Some(b);
            return Err(GpuError::Kernel {
                kernel: "crust field upload",
                message,
            });
        }
        self.upload_fields(&b, crust, fields);
        self.crust = Some(b);
        self.crust_synced = Some(after);
        self.check("crust field upload")
    }

    /// The host is authoritative again (a new crust was installed: resampling, load): forgets
    /// which fields the device held newer.
    pub fn supersede_device(&mut self) {
        self.device_newer = FieldMask::NONE;
    }

    /// Downloads the fields of `mask` that the device holds newer into `crust` and clears their
    /// bits; fields already in sync cost nothing. Write to the crust through
    /// `bypass_change_detection` (or [`sync_crust_to_host`]): a pull must not move the crust's
    /// change tick, or the next kernel would upload the whole crust again.
    pub fn pull(&mut self, crust: &mut Crust, mask: FieldMask) -> Result<(), GpuError> {
        const KERNEL: &str = "crust pull";
        let want = self.device_newer.and(mask);
        if want.is_empty() {
            return Ok(());
        }
        let Some((n, z, age, og, oga, fold, th)) = self.crust.as_ref().map(|b| {
            (
                b.len,
                b.elevation_km.clone(),
                b.age_my.clone(),
                b.orogeny.clone(),
                b.orogeny_age_my.clone(),
                b.fold_dir.clone(),
                b.thickness_km.clone(),
            )
        }) else {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: "the device holds newer fields but no crust buffers".into(),
            });
        };
        if crust.len() != n {
            return Err(GpuError::Kernel {
                kernel: KERNEL,
                message: format!("host crust has {} samples, device crust {n}", crust.len()),
            });
        }
        if want.contains(FieldMask::ELEVATION) {
            self.download(
                KERNEL,
                &z,
                bytemuck::cast_slice_mut(&mut crust.elevation_km),
            )?;
            self.device_newer.0 &= !FieldMask::ELEVATION.0;
        }
        if want.contains(FieldMask::THICKNESS) {
            self.download(
                KERNEL,
                &th,
                bytemuck::cast_slice_mut(&mut crust.thickness_km),
            )?;
            self.device_newer.0 &= !FieldMask::THICKNESS.0;
        }
        if want.contains(FieldMask::AGE) {
            self.download(KERNEL, &age, bytemuck::cast_slice_mut(&mut crust.age_my))?;
            self.device_newer.0 &= !FieldMask::AGE.0;
        }
        if want.contains(FieldMask::OROGENY_AGE) {
            self.download(
                KERNEL,
                &oga,
                bytemuck::cast_slice_mut(&mut crust.orogeny_age_my),
            )?;
            self.device_newer.0 &= !FieldMask::OROGENY_AGE.0;
        }
        if want.contains(FieldMask::FOLD_DIR) {
            self.download(KERNEL, &fold, bytemuck::cast_slice_mut(&mut crust.fold_dir))?;
            self.device_newer.0 &= !FieldMask::FOLD_DIR.0;
        }
        if want.contains(FieldMask::OROGENY) {
            let mut scratch = std::mem::take(&mut self.orogeny_scratch);
            scratch.resize(n, 0);
            let r = self.download(KERNEL, &og, &mut scratch);
            let decoded = r.and_then(|()| decode_orogeny(&scratch, &mut crust.orogeny, KERNEL));
            self.orogeny_scratch = scratch;
            decoded?;
            self.device_newer.0 &= !FieldMask::OROGENY.0;
        }
        Ok(())
    }
}

/// Decodes the device's orogeny bytes into `out`; errors name `kernel`.
pub(crate) fn decode_orogeny(
    bytes: &[u8],
    out: &mut [crate::resources::Orogeny],
    kernel: &'static str,
) -> Result<(), GpuError> {
    use crate::resources::Orogeny;
    let mut bad = None;
    for (i, (o, &b)) in out.iter_mut().zip(bytes).enumerate() {
        *o = match b {
            0 => Orogeny::None,
            1 => Orogeny::Andean,
            2 => Orogeny::Himalayan,
            _ => {
                bad = Some((i, b));
                Orogeny::None
            }
        };
    }
    match bad {
        Some((i, b)) => Err(GpuError::Kernel {
            kernel,
            message: format!("orogeny code {b} at sample {i}"),
        }),
        None => Ok(()),
    }
}

/// Pulls the fields of `mask` that the device holds newer into the world's [`Crust`] (without
/// moving its change tick); does nothing on the CPU backend. Call it before any CPU code reads
/// device-written fields or writes the crust (see docs/gpu-residency.md).
pub fn sync_crust_to_host(world: &mut World, mask: FieldMask) -> Result<(), GpuError> {
    if world
        .get_resource::<GpuContext>()
        .is_none_or(|g| g.device_newer.and(mask).is_empty())
    {
        return Ok(());
    }
    world.resource_scope(|world, mut gpu: Mut<GpuContext>| {
        match world.get_resource_mut::<Crust>() {
            Some(mut crust) => gpu.pull(crust.bypass_change_detection(), mask),
            None => Ok(()),
        }
    })
}

/// Writes the host [`Crust`] with `write`, which must change only the fields of `fields`; on the
/// GPU backend keeps the device copy current without a full upload when it can. If the device
/// was in sync with the host before the write and holds none of `fields` newer, `write` runs
/// on the host copy as it is (fields the device holds newer stay stale there and on the device)
/// and only `fields` go up afterwards ([`GpuContext::note_host_write`]; 4 B/sample for the
/// plate ids). Otherwise every stale field is pulled first and the next kernel uploads the
/// whole crust, as for any other host write. The crust's change tick moves as usual. A `write`
/// that changes a field outside `fields` leaves the device with old data there: declare every
/// field written.
pub fn write_crust_fields(
    world: &mut World,
    fields: FieldMask,
    write: impl FnOnce(&mut Crust),
) -> Result<(), GpuError> {
    let Some((before, len)) = world
        .get_resource_ref::<Crust>()
        .map(|c| (c.last_changed(), c.len()))
    else {
        return Ok(());
    };
    let declared = world
        .get_resource::<GpuContext>()
        .is_some_and(|g| g.failure.is_none() && g.can_declare_host_write(fields, len, before));
    if !declared {
        sync_crust_to_host(world, FieldMask::ALL)?;
    }
    let after = {
        let mut crust = world.resource_mut::<Crust>();
        write(&mut crust);
        crust.last_changed()
    };
    if !declared {
        return Ok(());
    }
    world.resource_scope(|world, mut gpu: Mut<GpuContext>| {
        gpu.note_host_write(world.resource::<Crust>(), fields, after)
    })
}

/// [`write_crust_fields`] from an exclusive system: on failure records the error in the context
/// (the step then stops with it) and returns false (`write` may not have run).
pub fn write_crust_fields_or_record(
    world: &mut World,
    fields: FieldMask,
    write: impl FnOnce(&mut Crust),
) -> bool {
    match write_crust_fields(world, fields, write) {
        Ok(()) => true,
        Err(e) => {
            if let Some(mut g) = world.get_resource_mut::<GpuContext>() {
                g.record_failure(e);
            }
            false
        }
    }
}

/// [`sync_crust_to_host`] from an exclusive system: on failure records the error in the context
/// (the step then stops with it) and returns false.
pub fn sync_crust_to_host_or_record(world: &mut World, mask: FieldMask) -> bool {
    match sync_crust_to_host(world, mask) {
        Ok(()) => true,
        Err(e) => {
            if let Some(mut g) = world.get_resource_mut::<GpuContext>() {
                g.record_failure(e);
            }
            false
        }
    }
}

/// From a system: pulls the fields of `mask` into `crust` (without moving its change tick).
/// On failure records the error in the context (the step then stops with it) and returns false.
pub fn pull_or_record(
    gpu: &mut GpuContext,
    crust: &mut impl DetectChangesMut<Inner = Crust>,
    mask: FieldMask,
) -> bool {
    if gpu.device_newer.and(mask).is_empty() {
        return true;
    }
    if gpu.failure.is_some() {
        return false;
    }
    match gpu.pull(crust.bypass_change_detection(), mask) {
        Ok(()) => true,
        Err(e) => {
            gpu.record_failure(e);
            false
        }
    }
}
