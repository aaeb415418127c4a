//! The long run: a planet over many steps, printing plate count, continental area, land fraction,
//! highest elevation, rifts, collisions and peak memory every 100 steps, then checking the
//! criteria of the rifting issue (plates 8–100, continental area within ±15%, land 0.15–0.5, no
//! NaN, peak memory at the end within 10% of that at step 100). Exits with status 1 if a seed
//! fails them.
//!
//! `cargo run --release --example long_run -- [samples] [steps] [seeds...]`
//! (defaults: 100,000 samples, 1000 steps, seeds 1–5; `PLANET_LOG` for logs, `RIFT_RATE` to try
//! another `rifting.frequency_per_my`, `TRACE_PEAK` to print every step that raised the peak
//! memory, with what happened in it, `EXIT_AT=N` to stop at step N without freeing anything, for a
//! heap profiler).
use tectonic_planets::prelude::*;
use tectonic_planets::resources::Sutures;
use tectonic_planets::systems::rifting::{RiftCause, RiftLog};

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};

/// The system allocator, counting the bytes the program holds (live heap) and their peak, so
/// that heap growth can be told apart from allocator fragmentation in the resident figures.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static LIVE_PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            let now = LIVE.fetch_add(l.size(), Relaxed) + l.size();
            LIVE_PEAK.fetch_max(now, Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size(), Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            if new >= l.size() {
                let now = LIVE.fetch_add(new - l.size(), Relaxed) + new - l.size();
                LIVE_PEAK.fetch_max(now, Relaxed);
            } else {
                LIVE.fetch_sub(l.size() - new, Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Live heap bytes now and their peak since the last call (which resets the peak).
fn heap() -> (usize, usize) {
    let now = LIVE.load(Relaxed);
    (now, LIVE_PEAK.swap(now, Relaxed))
}

/// A memory figure of this process from /proc/self/status (`VmHWM:` peak, `VmRSS:` now), bytes.
fn status_bytes(key: &str) -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// Peak resident memory (VmHWM), bytes.
fn peak_rss() -> u64 {
    status_bytes("VmHWM:")
}

/// Resident memory now (VmRSS), bytes.
fn rss() -> u64 {
    status_bytes("VmRSS:")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    if let Ok(f) = tracing_subscriber::EnvFilter::try_from_env("PLANET_LOG") {
        tracing_subscriber::fmt()
            .with_env_filter(f)
            .with_writer(std::io::stderr)
            .init();
    }
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let samples = args.first().copied().unwrap_or(100_000);
    let steps = args.get(1).copied().unwrap_or(1000);
    let seeds: Vec<u64> = if args.len() > 2 {
        args[2..].to_vec()
    } else {
        vec![1, 2, 3, 4, 5]
    };
    if seeds.len() > 1 {
        // One process per seed, so that each seed's peak memory is its own.
        let exe = std::env::current_exe()?;
        let mut failed = Vec::new();
        for seed in &seeds {
            let status = std::process::Command::new(&exe)
                .args([samples.to_string(), steps.to_string(), seed.to_string()])
                .status()?;
            if !status.success() {
                failed.push(*seed);
            }
        }
        if failed.is_empty() {
            println!("all seeds meet the long-run criteria");
            return Ok(());
        }
        println!("seeds failing the long-run criteria: {failed:?}");
        std::process::exit(1);
    }
    let mut failed = Vec::new();
    for seed in seeds {
        let mut p = Params::default();
        p.planet.samples = samples;
        p.planet.seed = seed;
        if let Ok(v) = std::env::var("RIFT_RATE") {
            p.rifting.frequency_per_my = v.parse()?;
        }
        let mut sim = Simulation::new(p)?;
        let c0 = sim.stats().continental_fraction;
        let t = std::time::Instant::now();
        let (mut plates_lo, mut plates_hi) = (usize::MAX, 0usize);
        let (mut land_lo, mut land_hi, mut zmax, mut worst) = (1.0f64, 0.0f64, f32::MIN, 0.0f64);
        let mut peak_at_100 = 0;
        let trace_peak = std::env::var_os("TRACE_PEAK").is_some();
        let exit_at: Option<u64> = std::env::var("EXIT_AT").ok().and_then(|v| v.parse().ok());
        let mut last_peak = peak_rss();
        for step in 1..=steps {
            let resamplings = sim.clock().resamplings;
            let rifts = sim.world().resource::<RiftLog>().events.len();
            let sutures = sim.world().resource::<Sutures>().total;
            sim.step()?;
            let (heap_now, heap_peak) = heap();
            if trace_peak && peak_rss() > last_peak {
                let p = peak_rss();
                println!(
                    "  step {step}: peak +{:.2} MB to {:.1} MB (resampled {}, rifts {}, collisions {}, plates {}, resident {:.1} MB, heap {:.1} MB, heap peak in step {:.1} MB)",
                    (p - last_peak) as f64 / 1e6,
                    p as f64 / 1e6,
                    sim.clock().resamplings - resamplings,
                    sim.world().resource::<RiftLog>().events.len() - rifts,
                    sim.world().resource::<Sutures>().total - sutures,
                    sim.stats().plates,
                    rss() as f64 / 1e6,
                    heap_now as f64 / 1e6,
                    heap_peak as f64 / 1e6
                );
                last_peak = p;
            }
            let s = sim.stats().clone();
            plates_lo = plates_lo.min(s.plates);
            plates_hi = plates_hi.max(s.plates);
            land_lo = land_lo.min(s.land_fraction);
            land_hi = land_hi.max(s.land_fraction);
            zmax = zmax.max(s.elevation_range_km.1);
            worst = worst.max((s.continental_fraction - c0).abs() / c0);
            if step == 100 {
                peak_at_100 = peak_rss();
            }
            if exit_at == Some(step) {
                // Without dropping anything, so that a heap profiler lists what is live now.
                std::process::exit(0);
            }
            if step % 100 == 0 || step == steps {
                let log = sim.world().resource::<RiftLog>();
                let random = log
                    .events
                    .iter()
                    .filter(|e| e.cause == RiftCause::Random)
                    .count();
                let state_mb = sim.state_bytes() as f64 / 1e6;
                let lost = sim
                    .world()
                    .resource::<tectonic_planets::systems::resample::ResampleWork>()
                    .continental_subducted_total_km2
                    / sim.mesh().total_area_km2();
                println!(
                    "seed {seed} step {step:>5} ({:>5.0} My): plates {:>3}, continental {:.3} ({:+.1}%), land {:.3}, max {:.2} km, rifts {random}, collisions {}, forced under {lost:.3}, state {:.1} MB, resident {:.0} MB, peak {:.0} MB, heap {:.1} MB",
                    sim.time_my(),
                    s.plates,
                    s.continental_fraction,
                    100.0 * (s.continental_fraction - c0) / c0,
                    s.land_fraction,
                    s.elevation_range_km.1,
                    sim.world().resource::<Sutures>().total,
                    state_mb,
                    rss() as f64 / 1e6,
                    peak_rss() as f64 / 1e6,
                    heap_now as f64 / 1e6,
                );
            }
        }
        let peak_end = peak_rss();
        let mem_growth = if peak_at_100 > 0 {
            peak_end as f64 / peak_at_100 as f64 - 1.0
        } else {
            0.0
        };
        let rift_ms: Vec<f64> = {
            let mut v: Vec<f64> = sim
                .world()
                .resource::<RiftLog>()
                .events
                .iter()
                .map(|e| e.elapsed_ms)
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        println!(
            "seed {seed}: plates {plates_lo}..{plates_hi}, land {land_lo:.3}..{land_hi:.3}, highest {zmax:.2} km, worst continental change {:.1}%, peak memory {:+.1}% from step 100 to {steps}, median rift {:.1} ms over {} rifts, {:.1} s",
            100.0 * worst,
            100.0 * mem_growth,
            rift_ms.get(rift_ms.len() / 2).copied().unwrap_or(f64::NAN),
            rift_ms.len(),
            t.elapsed().as_secs_f64()
        );
        let ok = (8..=100).contains(&plates_lo)
            && (8..=100).contains(&plates_hi)
            && worst <= 0.15
            && land_lo >= 0.15
            && land_hi <= 0.5
            && mem_growth <= 0.10;
        if !ok {
            failed.push(seed);
        }
    }
    if failed.is_empty() {
        println!("all seeds meet the long-run criteria");
        Ok(())
    } else {
        println!("seeds failing the long-run criteria: {failed:?}");
        std::process::exit(1);
    }
}
