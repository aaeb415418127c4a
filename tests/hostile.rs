//! Hostile input (issue #16): one case per failure of the issue's table, each run through the
//! `planet` binary and held to the same rules: a non-zero exit with a message naming the
//! problem, no panic or abort, wall time and peak memory (the child's, from `wait4`) under a
//! bound, and nothing destroyed (a FIFO is still a FIFO, a link's target is intact, the previous
//! save loads). One test per row of the table; the cases are in [`CASES`].
//!
//! `hostile_input_sweep` then tries several hundred more inputs (every flag with hostile
//! values, every kind of special file in every place a file is named, mutated saves, configs
//! and scripts) and counts how many were handled cleanly; all must be.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use tectonic_planets::Simulation;
use tectonic_planets::io::save;
use tectonic_planets::resources::params::Params;

// ---------------------------------------------------------------------------------------------
// Running the binary with a stopwatch and a memory meter.

/// How a run of `planet` ended.
#[derive(Debug)]
struct Run {
    /// Exit code, when it exited.
    code: Option<i32>,
    /// Signal, when one killed it.
    signal: Option<i32>,
    stderr: String,
    wall: Duration,
    /// Peak resident memory of the child, MB (`ru_maxrss` of `wait4`).
    peak_mb: f64,
    /// Killed for running past the timeout.
    timed_out: bool,
}

/// What to run: arguments, optional stdin, optional bytes to feed into a FIFO once the child
/// opens it (as `<(...)` does).
#[derive(Default)]
struct Input {
    args: Vec<OsString>,
    stdin: Option<Vec<u8>>,
    fifo_feed: Option<(PathBuf, Vec<u8>)>,
    /// Why the case cannot run here (it is then reported as skipped).
    skip: Option<String>,
}

fn args<I: IntoIterator<Item = S>, S: Into<OsString>>(v: I) -> Input {
    Input {
        args: v.into_iter().map(Into::into).collect(),
        ..Default::default()
    }
}

fn os(p: &Path) -> OsString {
    p.as_os_str().to_os_string()
}

/// Runs `planet` in `cwd`, killing it after `timeout`. The peak memory is the child's
/// `ru_maxrss` from `wait4`: an upper bound of its own peak (Linux counts in it what the child
/// held before `exec`, a copy of part of this test process), so the test process keeps its own
/// allocations small.
fn run_planet(input: &Input, cwd: &Path, timeout: Duration) -> Run {
    use std::process::{Command, Stdio};
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_planet"));
    cmd.args(&input.args)
        .current_dir(cwd)
        .env("PLANET_LOG", "error")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .stdin(if input.stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        });
    let started = Instant::now();
    // Reaped below with wait4 (for its rusage), not with `Child::wait`.
    #[allow(clippy::zombie_processes)]
    let mut child = cmd.spawn().expect("spawn planet");
    if let (Some(bytes), Some(mut pipe)) = (input.stdin.clone(), child.stdin.take()) {
        std::thread::spawn(move || {
            let _ = pipe.write_all(&bytes);
        });
    }
    if let Some((fifo, bytes)) = input.fifo_feed.clone() {
        std::thread::spawn(move || feed_fifo(&fifo, &bytes, Duration::from_secs(10)));
    }
    let mut err_pipe = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut err_pipe, &mut s);
        s
    });
    let pid = child.id() as libc::pid_t;
    let mut status: libc::c_int = 0;
    // SAFETY: a zeroed rusage is a valid value of the plain C struct wait4 fills.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let mut timed_out = false;
    loop {
        // SAFETY: `pid` is our child, not reaped yet; the pointers are to live locals.
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if r == pid {
            break;
        }
        assert!(r >= 0, "wait4 failed");
        if started.elapsed() > timeout {
            timed_out = true;
            // SAFETY: killing and reaping our own child.
            unsafe {
                libc::kill(pid, libc::SIGKILL);
                libc::wait4(pid, &mut status, 0, &mut usage);
            }
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let wall = started.elapsed();
    let stderr = String::from_utf8_lossy(&reader.join().unwrap_or_default()).into_owned();
    let (code, signal) = if libc::WIFEXITED(status) {
        (Some(libc::WEXITSTATUS(status)), None)
    } else if libc::WIFSIGNALED(status) {
        (None, Some(libc::WTERMSIG(status)))
    } else {
        (None, None)
    };
    Run {
        code,
        signal,
        stderr,
        wall,
        peak_mb: usage.ru_maxrss as f64 / 1024.0,
        timed_out,
    }
}

/// Writes `bytes` into the FIFO at `path` once a reader opens it (gives up after `timeout`).
fn feed_fifo(path: &Path, bytes: &[u8], timeout: Duration) {
    use std::os::unix::fs::OpenOptionsExt;
    let started = Instant::now();
    while started.elapsed() < timeout {
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
        {
            let _ = f.write_all(bytes);
            return;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn mkfifo(path: &Path) {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).unwrap();
    // SAFETY: a NUL-terminated path that outlives the call.
    let r = unsafe { libc::mkfifo(c.as_ptr(), 0o644) };
    assert_eq!(r, 0, "mkfifo {}", path.display());
}

fn is_fifo(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

fn is_symlink(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_symlink())
}

/// Peak resident memory of this test process, MB.
fn self_peak_mb() -> f64 {
    // SAFETY: a zeroed rusage is valid; getrusage fills it.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    u.ru_maxrss as f64 / 1024.0
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions.
    unsafe { libc::geteuid() == 0 }
}

// ---------------------------------------------------------------------------------------------
// Fixtures.

fn case_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("planet-hostile-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn small_params() -> Params {
    let mut p = Params::default();
    p.planet.samples = 1_000;
    p.init.plates = 6;
    p
}

/// A small valid save at `path`, `steps` steps in.
fn write_save(path: &Path, steps: u64) {
    let mut sim = Simulation::new(small_params()).unwrap();
    sim.run_steps(steps).unwrap();
    save::save_to_file(&mut sim, path).unwrap();
}

/// The step of the save at `path` (it must load).
fn save_step(path: &Path) -> u64 {
    save::load_from_file(path)
        .unwrap_or_else(|e| panic!("{} no longer loads: {e}", path.display()))
        .clock()
        .step
}

/// An LZ4 block that unpacks to `n` zero bytes: one literal zero, one match of `n - 6` bytes at
/// offset 1 (its length as a run of 255s: about `n / 255` bytes), five literal zeros.
fn lz4_zeros(n: u64) -> Vec<u8> {
    assert!(n >= 32);
    let mut b = vec![0x1F, 0x00, 0x01, 0x00];
    let mut rest = n - 6 - 4 - 15;
    b.reserve((rest / 255) as usize + 8);
    while rest >= 255 {
        b.push(255);
        rest -= 255;
    }
    b.push(rest as u8);
    b.push(0x50);
    b.extend_from_slice(&[0; 5]);
    b
}

/// A valid small save whose section `name` is replaced by an LZ4 block of `zeros` zero bytes,
/// with a correct header and checksum (the bomb of rows D and E).
fn lz4_bomb_save(name: &str, zeros: u64) -> Vec<u8> {
    let mut sim = Simulation::new(small_params()).unwrap();
    let good = save::save_to_bytes(&mut sim).unwrap();
    let sections = save::read_sections(&good, Path::new("good")).unwrap();
    let mut body = Vec::new();
    for s in &sections {
        body.extend_from_slice(&(s.name.len() as u16).to_le_bytes());
        body.extend_from_slice(s.name.as_bytes());
        body.extend_from_slice(&s.version.to_le_bytes());
        if s.name == name {
            let block = lz4_zeros(zeros);
            body.push(save::CODEC_LZ4);
            body.extend_from_slice(&zeros.to_le_bytes());
            body.extend_from_slice(&(block.len() as u64).to_le_bytes());
            body.extend_from_slice(&block);
        } else {
            body.push(save::CODEC_RAW);
            body.extend_from_slice(&(s.data.len() as u64).to_le_bytes());
            body.extend_from_slice(&(s.data.len() as u64).to_le_bytes());
            body.extend_from_slice(&s.data);
        }
    }
    let mut out = save::MAGIC.to_vec();
    out.extend_from_slice(&save::FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(sections.len() as u32).to_le_bytes());
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&body);
    let crc = save::checksum(&out);
    out[24..28].copy_from_slice(&crc.to_le_bytes());
    out
}

/// A PNG of `w × h` pixels of the given colour type (8-bit grey, 8-bit RGB, 16-bit grey).
fn write_png(path: &Path, colour: image::ColorType) {
    let (w, h) = (16u32, 16u32);
    let img: image::DynamicImage = match colour {
        image::ColorType::L8 => {
            image::GrayImage::from_fn(w, h, |x, y| image::Luma([(x * 7 + y) as u8])).into()
        }
        image::ColorType::Rgb8 => {
            image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 9])).into()
        }
        _ => image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(w, h, |x, y| {
            image::Luma([(x * 900 + y * 300) as u16])
        })
        .into(),
    };
    img.save(path).unwrap();
}

/// An exemplar folder with one `plain/e.png` of `colour` and, if given, its sidecar.
fn exemplar_dir(dir: &Path, colour: image::ColorType, sidecar: Option<&str>) -> PathBuf {
    let ex = dir.join("ex");
    std::fs::create_dir_all(ex.join("plain")).unwrap();
    write_png(&ex.join("plain/e.png"), colour);
    if let Some(s) = sidecar {
        std::fs::write(ex.join("plain/e.json"), s).unwrap();
    }
    ex
}

/// A little-endian TIFF whose image file directory has no entries.
fn empty_ifd_tiff() -> Vec<u8> {
    let mut b = b"II".to_vec();
    b.extend_from_slice(&42u16.to_le_bytes());
    b.extend_from_slice(&8u32.to_le_bytes());
    b.extend_from_slice(&0u16.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b
}

fn script(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

// ---------------------------------------------------------------------------------------------
// The cases.

/// What a case expects of the run.
#[derive(Clone, Copy, PartialEq)]
enum Expect {
    /// Exit 1 with every needle in the message.
    Refused(&'static [&'static str]),
    /// Exit 0.
    Succeeds,
}

/// One hostile input of the issue's table.
struct Case {
    /// The row of the issue's table.
    row: &'static str,
    /// What is tried.
    what: &'static str,
    /// Prepares its files in the case folder and gives the command line.
    setup: fn(&Path) -> Input,
    expect: Expect,
    /// Bounds: wall time (s) and peak memory (MB) of the child.
    max_s: f64,
    max_mb: f64,
    /// Checks after the run: nothing destroyed, the right files written or not.
    after: fn(&Path, &Run),
}

/// Bounds of a command that refuses before simulating anything.
const QUICK: (f64, f64) = (2.0, 200.0);
/// Bounds of a command that builds and runs a 1,000-sample planet for a few steps.
const SMALL_RUN: (f64, f64) = (20.0, 400.0);

fn nothing(_: &Path, _: &Run) {}

const GEN: [&str; 6] = ["generate", "--samples", "1000", "--plates", "6", "--quiet"];

fn gen_args(extra: &[&str]) -> Input {
    let mut v: Vec<&str> = GEN.to_vec();
    v.extend_from_slice(extra);
    args(v)
}

static CASES: &[Case] = &[
    // A: saving onto special files.
    Case {
        row: "A",
        what: "generate --save onto a FIFO",
        setup: |d| {
            mkfifo(&d.join("fifo.planet"));
            gen_args(&["--my", "2", "--out", "out", "--save", "./fifo.planet"])
        },
        expect: Expect::Refused(&["fifo.planet", "FIFO", "only replaces a regular file"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| {
            assert!(is_fifo(&d.join("fifo.planet")), "the FIFO was replaced");
            assert!(!d.join("out").exists(), "an output folder was made");
        },
    },
    Case {
        row: "A",
        what: "generate --save onto a symbolic link to a FIFO",
        setup: |d| {
            mkfifo(&d.join("fifo"));
            std::os::unix::fs::symlink("fifo", d.join("link.planet")).unwrap();
            gen_args(&["--my", "2", "--out", "out", "--save", "./link.planet"])
        },
        expect: Expect::Refused(&["link.planet", "symbolic link", "FIFO"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| {
            assert!(is_symlink(&d.join("link.planet")), "the link was replaced");
            assert!(is_fifo(&d.join("fifo")), "the FIFO was replaced");
        },
    },
    Case {
        row: "A",
        what: "generate --save onto a character device",
        setup: |d| {
            let node = d.join("null.planet");
            if is_root() {
                use std::os::unix::ffi::OsStrExt;
                let c = std::ffi::CString::new(node.as_os_str().as_bytes()).unwrap();
                // SAFETY: a NUL-terminated path; makedev(1, 3) is the null device.
                let r =
                    unsafe { libc::mknod(c.as_ptr(), libc::S_IFCHR | 0o666, libc::makedev(1, 3)) };
                if r != 0 {
                    // As root without CAP_MKNOD: never point a save at the real /dev/null.
                    return Input {
                        skip: Some("root without mknod: no private character device".into()),
                        ..Default::default()
                    };
                }
                gen_args(&["--my", "2", "--out", "out", "--save", "./null.planet"])
            } else {
                // Not root: /dev/null cannot be replaced anyway; the message must still name it.
                gen_args(&["--my", "2", "--out", "out", "--save", "/dev/null"])
            }
        },
        expect: Expect::Refused(&["character device", "only replaces a regular file"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| {
            use std::os::unix::fs::FileTypeExt;
            let node = if is_root() {
                d.join("null.planet")
            } else {
                PathBuf::from("/dev/null")
            };
            let m = std::fs::symlink_metadata(&node).unwrap();
            assert!(m.file_type().is_char_device(), "the device was replaced");
        },
    },
    Case {
        row: "A",
        what: "generate --save through a symbolic link to a save",
        setup: |d| {
            std::fs::create_dir_all(d.join("real")).unwrap();
            write_save(&d.join("real/a.planet"), 0);
            std::os::unix::fs::symlink("real/a.planet", d.join("link.planet")).unwrap();
            gen_args(&["--my", "4", "--out", "out", "--save", "./link.planet"])
        },
        expect: Expect::Succeeds,
        max_s: SMALL_RUN.0,
        max_mb: SMALL_RUN.1,
        after: |d, _| {
            assert!(is_symlink(&d.join("link.planet")), "the link was replaced");
            assert_eq!(save_step(&d.join("real/a.planet")), 2, "written through");
        },
    },
    Case {
        row: "A",
        what: "generate --save onto a dangling symbolic link",
        setup: |d| {
            std::os::unix::fs::symlink("nowhere/x.planet", d.join("dangling.planet")).unwrap();
            gen_args(&["--my", "2", "--out", "out", "--save", "./dangling.planet"])
        },
        expect: Expect::Refused(&["dangling.planet", "does not exist"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(is_symlink(&d.join("dangling.planet"))),
    },
    // B: reading endless devices.
    Case {
        row: "B",
        what: "resume /dev/zero",
        setup: |_| args(["resume", "/dev/zero", "--my", "1"]),
        expect: Expect::Refused(&["/dev/zero", "character device", "not a save file"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "B",
        what: "export /dev/urandom",
        setup: |_| args(["export", "/dev/urandom", "--out", "out"]),
        expect: Expect::Refused(&["/dev/urandom", "character device"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "B",
        what: "resume a 2 GB file of zeros (sparse)",
        setup: |d| {
            let f = std::fs::File::create(d.join("zeros.planet")).unwrap();
            f.set_len(2 << 30).unwrap();
            args(["resume", "zeros.planet", "--my", "1"])
        },
        expect: Expect::Refused(&["zeros.planet", "not a planet save"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // C: a FIFO as a save.
    Case {
        row: "C",
        what: "resume a named FIFO",
        setup: |d| {
            mkfifo(&d.join("pipe.planet"));
            args(["resume", "pipe.planet", "--my", "1"])
        },
        expect: Expect::Refused(&["pipe.planet", "FIFO", "not a save file"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(is_fifo(&d.join("pipe.planet"))),
    },
    // D, E: LZ4 bombs in sections.
    Case {
        row: "D",
        what: "core.params: an LZ4 block of 663 MB of NULs in a 2.6 MB file",
        setup: |d| {
            std::fs::write(
                d.join("bomb.planet"),
                lz4_bomb_save("core.params", 663 << 20),
            )
            .unwrap();
            args(["resume", "bomb.planet", "--my", "1"])
        },
        expect: Expect::Refused(&["bomb.planet", "core.params", "uncompressed", "1 MiB"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "D",
        what: "core.params: an LZ4 block of 2.8 GB of NULs in an 11 MB file",
        setup: |d| {
            std::fs::write(
                d.join("bomb.planet"),
                lz4_bomb_save("core.params", 2_800_000_000),
            )
            .unwrap();
            args(["export", "bomb.planet", "--out", "out"])
        },
        expect: Expect::Refused(&["bomb.planet", "core.params", "uncompressed"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "E",
        what: "core.history: an LZ4 block of 663 MB of NULs",
        setup: |d| {
            std::fs::write(
                d.join("bomb.planet"),
                lz4_bomb_save("core.history", 663 << 20),
            )
            .unwrap();
            args(["resume", "bomb.planet", "--my", "1"])
        },
        expect: Expect::Refused(&["bomb.planet", "core.history", "uncompressed", "64 MiB"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "E",
        what: "core.history: 60 MiB of NULs, under the cap",
        setup: |d| {
            std::fs::write(
                d.join("bomb.planet"),
                lz4_bomb_save("core.history", 60 << 20),
            )
            .unwrap();
            args(["resume", "bomb.planet", "--my", "1"])
        },
        expect: Expect::Refused(&["bomb.planet", "core.history", "unread bytes"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // F: configs without end or too large.
    Case {
        row: "F",
        what: "--config /dev/zero",
        setup: |_| gen_args(&["--config", "/dev/zero", "--my", "2", "--out", "out"]),
        expect: Expect::Refused(&["/dev/zero", "larger than 1 MiB"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists(), "a config error made --out"),
    },
    Case {
        row: "F",
        what: "--config of 31 MB of unknown keys",
        setup: |d| {
            // Written in pieces, so that this test process stays small (see `run_planet`).
            let mut f = std::io::BufWriter::new(std::fs::File::create(d.join("big.toml")).unwrap());
            let (mut k, mut len) = (0u64, 0usize);
            while len < 31_000_000 {
                let line = format!("unknown_key_{k} = 1\n");
                f.write_all(line.as_bytes()).unwrap();
                len += line.len();
                k += 1;
            }
            f.flush().unwrap();
            gen_args(&["--config", "big.toml", "--my", "2", "--out", "out"])
        },
        expect: Expect::Refused(&["big.toml", "larger than 1 MiB"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // G: a config read from a pipe is read once.
    Case {
        row: "G",
        what: "--config /dev/stdin with an out-of-range plugin value",
        setup: |_| Input {
            stdin: Some(b"[plugins.hotspots]\nradius_km = -5\n".to_vec()),
            ..gen_args(&["--config", "/dev/stdin", "--my", "2", "--out", "out"])
        },
        expect: Expect::Refused(&["plugins.hotspots.radius_km", "out of range"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "G",
        what: "--config <(...): a FIFO with an out-of-range plugin value",
        setup: |d| {
            let fifo = d.join("config.fifo");
            mkfifo(&fifo);
            Input {
                fifo_feed: Some((
                    fifo.clone(),
                    b"[plugins.hotspots]\nradius_km = 1e9\n".to_vec(),
                )),
                ..gen_args(&["--config", "config.fifo", "--my", "2", "--out", "out"])
            }
        },
        expect: Expect::Refused(&["plugins.hotspots.radius_km", "out of range"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // I: threads.
    Case {
        row: "I",
        what: "--threads 1000",
        setup: |_| gen_args(&["--threads", "1000", "--my", "2", "--out", "out"]),
        expect: Expect::Refused(&["--threads 1000", "at most"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "I",
        what: "--threads 100000",
        setup: |_| gen_args(&["--threads", "100000", "--my", "2", "--out", "out"]),
        expect: Expect::Refused(&["--threads 100000", "at most"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // J: runs that would never end.
    Case {
        row: "J",
        what: "generate --my 1e12",
        setup: |_| args(["generate", "--my", "1e12", "--out", "out"]),
        expect: Expect::Refused(&["--my", "steps", "years"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "J",
        what: "bench --steps 1000000000",
        setup: |_| args(["bench", "--steps", "1000000000"]),
        expect: Expect::Refused(&["--steps 1000000000", "days"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "J",
        what: "resume --my 1e15 of a good save",
        setup: |d| {
            write_save(&d.join("good.planet"), 2);
            args(["resume", "good.planet", "--my", "1e15"])
        },
        expect: Expect::Refused(&["--my", "years"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert_eq!(save_step(&d.join("good.planet")), 2),
    },
    // K: scripts checked before the run; a late failure keeps the work.
    Case {
        row: "K",
        what: "a script event at 190 My naming an unknown phenomenon",
        setup: |d| {
            script(
                d,
                "s.toml",
                "[[event]]\nat_my = 190\ncommand = \"set_phenomenon\"\nname = \"volcanoez\"\nenabled = true\n",
            );
            gen_args(&[
                "--my",
                "200",
                "--script",
                "s.toml",
                "--save",
                "./k.planet",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["event 1", "190 My", "set_phenomenon", "volcanoez"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| {
            assert!(!d.join("k.planet").exists());
            assert!(!d.join("out").exists());
        },
    },
    Case {
        row: "K",
        what: "a script event at 190 My setting an unknown plugin parameter",
        setup: |d| {
            script(
                d,
                "s.toml",
                "[[event]]\nat_my = 190\ncommand = \"set_param\"\nkey = \"plugins.hotspots.radius\"\nvalue = 3\n",
            );
            gen_args(&[
                "--my",
                "200",
                "--script",
                "s.toml",
                "--save",
                "./k.planet",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["event 1", "plugins.hotspots.radius"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("k.planet").exists()),
    },
    Case {
        row: "K",
        what: "a script event at 4 My naming a plate no rift made: the planet is kept",
        setup: |d| {
            script(
                d,
                "s.toml",
                "[[event]]\nat_my = 4\ncommand = \"rift_at\"\nplate = 9999\nfragments = 2\n",
            );
            gen_args(&[
                "--my",
                "10",
                "--script",
                "s.toml",
                "--save",
                "./k.planet",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&[
            "event 1",
            "9999",
            "stopped at 4 My",
            "saved to ./k.planet",
            "maps written to out",
        ]),
        max_s: SMALL_RUN.0,
        max_mb: SMALL_RUN.1,
        after: |d, _| {
            assert_eq!(save_step(&d.join("k.planet")), 2, "the planet at 4 My");
            assert!(d.join("out/elevation.png").is_file());
        },
    },
    // L: an output folder that cannot be written, found before the run; a late failure.
    Case {
        row: "L",
        what: "--out under a regular file, with a writable --save",
        setup: |d| {
            std::fs::write(d.join("file"), b"x").unwrap();
            gen_args(&["--my", "20", "--save", "./l.planet", "--out", "file/out"])
        },
        expect: Expect::Refused(&["file/out", "Not a directory"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("l.planet").exists(), "nothing ran, nothing saved"),
    },
    Case {
        row: "L",
        what: "a map snapshot that fails in the middle of the run: the save is still written",
        setup: |d| {
            std::fs::create_dir_all(d.join("out")).unwrap();
            std::fs::write(d.join("out/t0004My"), b"in the way").unwrap();
            gen_args(&[
                "--my",
                "8",
                "--maps-every",
                "2",
                "--save",
                "./l.planet",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["t0004My", "stopped at 4 My", "saved to ./l.planet"]),
        max_s: SMALL_RUN.0,
        max_mb: SMALL_RUN.1,
        after: |d, _| {
            assert_eq!(save_step(&d.join("l.planet")), 2);
            assert_eq!(std::fs::read(d.join("out/t0004My")).unwrap(), b"in the way");
        },
    },
    // M: temporary files of killed saves.
    Case {
        row: "M",
        what: "stale .NAME.PID.tmp files of the same save are removed by the next save",
        setup: |d| {
            let dead = {
                let mut c = std::process::Command::new("true").spawn().unwrap();
                let pid = c.id();
                c.wait().unwrap();
                pid
            };
            for f in [
                format!(".m.planet.{dead}.tmp"),
                format!(".m.planet.{}.tmp", 4_194_304 + 7),
                format!(".m.planet.{}.tmp", std::process::id()),
                format!(".other.planet.{dead}.tmp"),
                ".m.planet.notapid.tmp".to_string(),
            ] {
                std::fs::write(d.join(f), b"partial").unwrap();
            }
            gen_args(&["--my", "2", "--save", "./m.planet", "--out", "out"])
        },
        expect: Expect::Succeeds,
        max_s: SMALL_RUN.0,
        max_mb: SMALL_RUN.1,
        after: |d, _| {
            let left: Vec<String> = std::fs::read_dir(d)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".tmp"))
                .collect();
            let mine = format!(".m.planet.{}.tmp", std::process::id());
            assert!(
                left.contains(&mine),
                "a live process's file was removed: {left:?}"
            );
            assert!(
                left.iter().any(|n| n.starts_with(".other.planet.")),
                "{left:?}"
            );
            assert!(
                left.contains(&".m.planet.notapid.tmp".to_string()),
                "{left:?}"
            );
            assert_eq!(left.len(), 3, "stale files left: {left:?}");
            assert_eq!(save_step(&d.join("m.planet")), 1);
        },
    },
    // N: exports whose size is known are checked before they start.
    Case {
        row: "N",
        what: "a 14.5°×14.5° regional export at 100 m",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--geotiff",
                "--amplified",
                "--region",
                "0,0,14.5,14.5",
                "--resolution",
                "100m",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["16122×16122", "GiB", "split the region into tiles"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists(), "files or folders were left"),
    },
    // O: exemplars as the docs say.
    Case {
        row: "O",
        what: "an 8-bit RGB exemplar PNG",
        setup: |d| {
            exemplar_dir(d, image::ColorType::Rgb8, None);
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--amplified-width",
                "64",
                "--exemplars",
                "ex",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["e.png", "8-bit RGB", "16-bit greyscale"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "O",
        what: "an 8-bit grey exemplar PNG",
        setup: |d| {
            exemplar_dir(d, image::ColorType::L8, None);
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--amplified-width",
                "64",
                "--exemplars",
                "ex",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["e.png", "8-bit grey", "16-bit greyscale"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "O",
        what: "a sidecar with min > max",
        setup: |d| {
            exemplar_dir(
                d,
                image::ColorType::L16,
                Some(r#"{"min_elevation_m": 3000, "max_elevation_m": 100}"#),
            );
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--amplified-width",
                "64",
                "--exemplars",
                "ex",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["e.json", "min_elevation_m", "must be below"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "O",
        what: "a sidecar of ±1e30 m",
        setup: |d| {
            exemplar_dir(
                d,
                image::ColorType::L16,
                Some(r#"{"min_elevation_m": -1e30, "max_elevation_m": 1e30}"#),
            );
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--amplified-width",
                "64",
                "--exemplars",
                "ex",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["e.json", "-1e30", "20000"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // P: parameters that must be ordered.
    Case {
        row: "P",
        what: "continental crust starting below oceanic crust",
        setup: |d| {
            std::fs::write(
                d.join("c.toml"),
                "[init]\ncontinental_elevation_km = -2\noceanic_elevation_km = 0\n",
            )
            .unwrap();
            gen_args(&["--config", "c.toml", "--my", "2", "--out", "out"])
        },
        expect: Expect::Refused(&[
            "c.toml",
            "init.oceanic_elevation_km = 0.0",
            "init.continental_elevation_km = -2.0",
            "below",
        ]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "P",
        what: "subduction.control_distance_km beyond subduction.distance_km",
        setup: |d| {
            std::fs::write(
                d.join("c.toml"),
                "[subduction]\ncontrol_distance_km = 2000\ndistance_km = 1800\n",
            )
            .unwrap();
            gen_args(&["--config", "c.toml", "--my", "2", "--out", "out"])
        },
        expect: Expect::Refused(&[
            "subduction.control_distance_km = 2000.0",
            "subduction.distance_km = 1800.0",
        ]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "P",
        what: "continents starting above the highest continental altitude",
        setup: |d| {
            std::fs::write(
                d.join("c.toml"),
                "[init]\ncontinental_elevation_km = 5\n[continent]\nmax_elevation_km = 2\n",
            )
            .unwrap();
            gen_args(&["--config", "c.toml", "--my", "2", "--out", "out"])
        },
        expect: Expect::Refused(&[
            "init.continental_elevation_km = 5.0",
            "continent.max_elevation_km = 2.0",
        ]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // Q: messages.
    Case {
        row: "Q",
        what: "a 1 MB key is not echoed in full",
        setup: |d| {
            let key = "k".repeat(1_000_000);
            std::fs::write(d.join("c.toml"), format!("[ocean]\n{key} = 1\n")).unwrap();
            gen_args(&["--config", "c.toml", "--my", "2", "--out", "out"])
        },
        expect: Expect::Refused(&["unknown parameter", "ocean.kkkk", "…"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| {
            assert!(
                r.stderr.len() < 2_000,
                "{} bytes of message",
                r.stderr.len()
            )
        },
    },
    Case {
        row: "Q",
        what: "--region=NaN,... says not a number, not empty",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--geotiff",
                "--region=NaN,0,1,1",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["LAT0", "NaN", "not a finite number"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| assert!(!r.stderr.contains("empty"), "{}", r.stderr),
    },
    Case {
        row: "Q",
        what: "--resolution 1e-300m prints no 300-digit number",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--geotiff",
                "--region",
                "0,0,1,1",
                "--resolution",
                "1e-300m",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["1e-300m", "pixel size", "out of range"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| {
            let longest = r
                .stderr
                .split(|c: char| !c.is_ascii_digit())
                .map(str::len)
                .max();
            assert!(longest.unwrap_or(0) < 20, "{}", r.stderr);
        },
    },
    Case {
        row: "Q",
        what: "a TIFF exemplar with an empty directory is not called tiled",
        setup: |d| {
            std::fs::create_dir_all(d.join("ex/plain")).unwrap();
            std::fs::write(d.join("ex/plain/e.tif"), empty_ifd_tiff()).unwrap();
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--amplified-width",
                "64",
                "--exemplars",
                "ex",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["e.tif", "directory is empty"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| assert!(!r.stderr.contains("tiled"), "{}", r.stderr),
    },
    Case {
        row: "Q",
        what: "--exemplars naming a file says so once",
        setup: |d| {
            std::fs::write(d.join("notdir"), b"x").unwrap();
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--exemplars",
                "notdir",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["notdir", "must name a folder", "regular file"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| {
            assert!(
                !r.stderr.contains("not a folder: not a folder"),
                "{}",
                r.stderr
            )
        },
    },
    Case {
        row: "Q",
        what: "a missing exemplar folder: the OS error said once",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--amplified",
                "--exemplars",
                "missing",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["missing", "No such file or directory"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| assert_eq!(r.stderr.matches("No such file").count(), 1, "{}", r.stderr),
    },
    Case {
        row: "Q",
        what: "a save under a regular file: the OS error said once",
        setup: |d| {
            std::fs::write(d.join("file"), b"x").unwrap();
            gen_args(&["--my", "2", "--save", "./file/x.planet", "--out", "out"])
        },
        expect: Expect::Refused(&["file/x.planet", "Not a directory"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |_, r| {
            assert_eq!(
                r.stderr.matches("Not a directory").count(),
                1,
                "{}",
                r.stderr
            )
        },
    },
    Case {
        row: "Q",
        what: "a bad script event is named by its number, time and command",
        setup: |d| {
            script(
                d,
                "s.toml",
                "[[event]]\nat_my = 5\ncommand = \"uplift\"\ncap = { lat = 0, lon = 0, radius_km = 500 }\ndelta_km = 1\n\n[[event]]\nat_my = 2\ncommand = \"set_motion\"\nplate = 1\npole = { lat = 0, lon = 0 }\nspeed_mm_per_yr = 5000\n",
            );
            gen_args(&["--my", "10", "--script", "s.toml", "--out", "out"])
        },
        expect: Expect::Refused(&["event 2", "at 2 My", "set_motion", "speed_mm_per_yr"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    // R: input that used to be silently ignored.
    Case {
        row: "R",
        what: "--resolution abc without --region",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args(["export", "s.planet", "--resolution", "abc", "--out", "out"])
        },
        expect: Expect::Refused(&["--resolution abc", "--region"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("out").exists()),
    },
    Case {
        row: "R",
        what: "a region with LAT0 north of LAT1",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--geotiff",
                "--region",
                "10,0,5,5",
                "--out",
                "out",
            ])
        },
        expect: Expect::Refused(&["LAT0 must be south of LAT1"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
    Case {
        row: "R",
        what: "a region across the antimeridian can be asked for",
        setup: |d| {
            write_save(&d.join("s.planet"), 0);
            args([
                "export",
                "s.planet",
                "--no-maps",
                "--geotiff",
                "--region",
                "0,170,2,-170",
                "--resolution",
                "0.5deg",
                "--out",
                "out",
            ])
        },
        expect: Expect::Succeeds,
        max_s: SMALL_RUN.0,
        max_mb: SMALL_RUN.1,
        after: |d, _| {
            let t = tectonic_planets::io::geotiff::read_single_band(
                &std::fs::read(d.join("out/tile_plate.tif")).unwrap(),
            )
            .unwrap();
            assert_eq!((t.width, t.height), (40, 4), "20° by 2° at 0.5°");
        },
    },
    Case {
        row: "R",
        what: "a config error creates no --out folder",
        setup: |d| {
            std::fs::write(d.join("c.toml"), "[ocean]\nridge = 1\n").unwrap();
            gen_args(&["--config", "c.toml", "--my", "2", "--out", "newout"])
        },
        expect: Expect::Refused(&["c.toml", "ocean.ridge"]),
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: |d, _| assert!(!d.join("newout").exists()),
    },
    Case {
        row: "R",
        what: "--help names the file a regional heightmap is written to",
        setup: |_| args(["export", "--help"]),
        expect: Expect::Succeeds,
        max_s: QUICK.0,
        max_mb: QUICK.1,
        after: nothing,
    },
];

/// Runs every case of `row`, each in its own folder, and fails naming each case that broke a
/// rule.
fn run_row(row: &str) {
    let mut failures = Vec::new();
    let mut ran = 0;
    for (k, case) in CASES.iter().enumerate().filter(|(_, c)| c.row == row) {
        let dir = case_dir(&format!("{row}{k}"));
        let input = (case.setup)(&dir);
        if let Some(why) = &input.skip {
            eprintln!("row {row}: {}: SKIPPED ({why})", case.what);
            continue;
        }
        let run = run_planet(
            &input,
            &dir,
            Duration::from_secs_f64(case.max_s * 3.0 + 5.0),
        );
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            check_run(case, &run);
            (case.after)(&dir, &run);
        }));
        eprintln!(
            "row {row}: {}: exit {:?}, {:.2} s, {:.0} MB (test process {:.0} MB){}",
            case.what,
            run.code,
            run.wall.as_secs_f64(),
            run.peak_mb,
            self_peak_mb(),
            if outcome.is_ok() { "" } else { "  FAILED" }
        );
        if let Err(e) = outcome {
            let msg = e
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            failures.push(format!("{}: {msg}", case.what));
        } else {
            let _ = std::fs::remove_dir_all(&dir);
        }
        ran += 1;
    }
    assert!(ran > 0, "row {row} has no case that ran");
    assert!(failures.is_empty(), "row {row}:\n{}", failures.join("\n"));
}

/// The rules every case is held to.
fn check_run(case: &Case, run: &Run) {
    let err = &run.stderr;
    assert!(!run.timed_out, "still running after {:?}: {err}", run.wall);
    assert_eq!(run.signal, None, "killed by a signal: {err}");
    assert!(!err.contains("panicked"), "panicked: {err}");
    assert!(!err.contains("memory allocation"), "aborted: {err}");
    assert!(err.len() < 16_000, "{} bytes of stderr", err.len());
    match case.expect {
        Expect::Refused(needles) => {
            assert_eq!(run.code, Some(1), "expected a refusal: {err}");
            assert!(err.contains("error: "), "{err}");
            for n in needles {
                assert!(err.contains(n), "the message lacks {n:?}: {err}");
            }
        }
        Expect::Succeeds => assert_eq!(run.code, Some(0), "expected success: {err}"),
    }
    assert!(
        run.wall.as_secs_f64() < case.max_s,
        "took {:.2} s (bound {} s)",
        run.wall.as_secs_f64(),
        case.max_s
    );
    assert!(
        run.peak_mb < case.max_mb,
        "peak memory {:.0} MB (bound {} MB)",
        run.peak_mb,
        case.max_mb
    );
}

#[test]
fn a_saves_never_replace_special_files() {
    run_row("A");
}

#[test]
fn b_endless_devices_are_not_read() {
    run_row("B");
}

#[test]
fn c_a_fifo_save_does_not_hang() {
    run_row("C");
}

#[test]
fn d_lz4_bomb_in_core_params_is_refused_unread() {
    run_row("D");
}

#[test]
fn e_lz4_bomb_in_core_history_is_refused_unread() {
    run_row("E");
}

#[test]
fn f_config_size_is_capped() {
    run_row("F");
}

#[test]
fn g_config_from_a_pipe_is_read_once() {
    run_row("G");
}

#[test]
fn i_thread_count_is_capped() {
    run_row("I");
}

#[test]
fn j_endless_runs_are_refused_with_an_estimate() {
    run_row("J");
}

#[test]
fn k_script_errors_come_first_or_keep_the_work() {
    run_row("K");
}

#[test]
fn l_unwritable_outputs_are_found_first_and_the_save_is_kept() {
    run_row("L");
}

#[test]
fn m_stale_temporary_saves_are_cleaned() {
    run_row("M");
}

#[test]
fn n_oversized_exports_are_refused_up_front() {
    run_row("N");
}

#[test]
fn o_exemplars_are_checked_as_documented() {
    run_row("O");
}

#[test]
fn p_ordered_parameter_pairs_are_checked() {
    run_row("P");
}

#[test]
fn q_messages_say_what_and_where_once() {
    run_row("Q");
}

#[test]
fn r_nothing_is_silently_ignored() {
    run_row("R");
    let help = std::process::Command::new(env!("CARGO_BIN_EXE_planet"))
        .args(["export", "--help"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(text.contains("tile_amplified16.png"), "{text}");
    assert!(!text.contains("`tile16.png`"), "{text}");
}

/// Two runs saving to one path: the one that finds the file replaced since it last saw it
/// leaves it alone and says so ([`save::save_to_file_checked`]), instead of the last writer
/// silently winning.
#[test]
fn a_save_replaced_by_another_writer_is_left_alone() {
    let dir = case_dir("writers");
    let path = dir.join("shared.planet");
    let mut mine = Simulation::new(small_params()).unwrap();
    let mut seen = save::FileStamp::of(&path);
    assert_eq!(seen, None);
    save::save_to_file_checked(&mut mine, &path, &mut seen).unwrap();
    assert!(seen.is_some());
    // Another program writes the same file.
    write_save(&path, 3);
    mine.run_steps(1).unwrap();
    let e = save::save_to_file_checked(&mut mine, &path, &mut seen).unwrap_err();
    assert!(matches!(e, save::SaveError::Replaced { .. }), "{e}");
    assert!(e.to_string().contains("shared.planet"), "{e}");
    assert_eq!(save_step(&path), 3, "the other program's save is intact");
    // Once the file is seen again, saving goes on.
    seen = save::FileStamp::of(&path);
    save::save_to_file_checked(&mut mine, &path, &mut seen).unwrap();
    assert_eq!(save_step(&path), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------------------------------------
// The sweep.

/// Whether a run handled its input cleanly: it exited 0, 1 (an error) or 2 (clap's usage
/// error), with no signal, panic or abort, a bounded message that says `error:` when it
/// failed, within the time and memory bounds.
fn clean(run: &Run, max_s: f64, max_mb: f64) -> Result<(), String> {
    let err = &run.stderr;
    let short = |s: &str| s.chars().take(300).collect::<String>();
    if run.timed_out {
        return Err(format!("timed out: {}", short(err)));
    }
    if let Some(sig) = run.signal {
        return Err(format!("signal {sig}: {}", short(err)));
    }
    if err.contains("panicked") || err.contains("memory allocation") {
        return Err(format!("panic or abort: {}", short(err)));
    }
    if err.len() > 16_000 {
        return Err(format!("{} bytes of stderr", err.len()));
    }
    match run.code {
        Some(0) => {}
        Some(1) | Some(2) if err.contains("error:") => {}
        c => return Err(format!("exit {c:?}: {}", short(err))),
    }
    if run.wall.as_secs_f64() > max_s {
        return Err(format!("{:.1} s", run.wall.as_secs_f64()));
    }
    if run.peak_mb > max_mb {
        return Err(format!("{:.0} MB", run.peak_mb));
    }
    Ok(())
}

/// Flags and the hostile values they are tried with.
fn flag_values() -> Vec<(&'static str, Vec<String>)> {
    let long = "9".repeat(5000);
    let numbers: Vec<String> = [
        "",
        "-1",
        "0",
        "NaN",
        "nan",
        "inf",
        "-inf",
        "1e308",
        "1e-308",
        "1e-300",
        "abc",
        "😀",
        "18446744073709551616",
        "0x10",
        "1_000",
        " 5",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([long])
    .collect();
    vec![
        ("--my", numbers.clone()),
        ("--seed", numbers.clone()),
        ("--samples", numbers.clone()),
        ("--plates", numbers.clone()),
        ("--continental-fraction", numbers.clone()),
        ("--threads", numbers.clone()),
        ("--width", numbers.clone()),
        ("--save-every", numbers.clone()),
        ("--maps-every", numbers.clone()),
        (
            "--disable",
            vec![
                "erosionn".into(),
                "".into(),
                ",,,".into(),
                "x".repeat(100_000),
            ],
        ),
        (
            "--enable",
            vec!["all".into(), "hotspots,hotspots".into(), "😀".into()],
        ),
        ("--backend", vec!["gpuu".into(), "".into(), "CPU".into()]),
    ]
}

/// Export flags and their hostile values (run on a good save with `--no-maps`).
fn export_values() -> Vec<(&'static str, Vec<String>)> {
    vec![
        (
            "--region",
            [
                "",
                "1,2,3",
                "1,2,3,4,5",
                "NaN,0,1,1",
                "0,0,inf,1",
                "-91,0,0,1",
                "0,-181,1,0",
                "0,0,0,0",
                "5,5,1,1",
                "0,179,1,-179",
                "-90,-180,90,180",
                "0,0,1e-9,1e-9",
                "a,b,c,d",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
        ),
        (
            "--resolution",
            [
                "", "0m", "-1km", "1e-300m", "1e300deg", "NaN", "100", "100 m", "5 km", "0.001DEG",
                "fastest",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
        ),
        (
            "--amplified-width",
            ["0", "1", "3", "20000", "-4", "abc"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ),
        (
            "--relief-scale",
            ["-1", "NaN", "inf", "11", "0"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ),
        (
            "--gltf-segments",
            ["0", "7", "8193", "4294967295"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ),
        (
            "--exaggeration",
            ["-1", "NaN", "1e308", "1001"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ),
    ]
}

/// Every kind of file system entry in every place the command line names a file.
fn special_paths(dir: &Path) -> Vec<(String, PathBuf)> {
    let fifo = dir.join("sweep.fifo");
    if !fifo.exists() {
        mkfifo(&fifo);
    }
    let _ = std::os::unix::fs::symlink("loop2", dir.join("loop1"));
    let _ = std::os::unix::fs::symlink("loop1", dir.join("loop2"));
    let _ = std::os::unix::fs::symlink("/nonexistent/x", dir.join("dangling"));
    let _ = std::os::unix::fs::symlink("sweep.fifo", dir.join("to-fifo"));
    std::fs::create_dir_all(dir.join("a-folder")).unwrap();
    std::fs::write(dir.join("empty"), b"").unwrap();
    std::fs::write(dir.join("text"), b"hello\n").unwrap();
    let f = std::fs::File::create(dir.join("sparse")).unwrap();
    f.set_len(1 << 30).unwrap();
    let mut v: Vec<(String, PathBuf)> = [
        "/dev/zero",
        "/dev/null",
        "/dev/urandom",
        "/proc/self/status",
        "/",
        "/nonexistent/file",
    ]
    .iter()
    .map(|p| (p.to_string(), PathBuf::from(p)))
    .collect();
    for name in [
        "sweep.fifo",
        "loop1",
        "dangling",
        "to-fifo",
        "a-folder",
        "empty",
        "text",
        "sparse",
    ] {
        v.push((name.to_string(), dir.join(name)));
    }
    v
}

/// Several hundred hostile inputs through the binary (flags, special files, mutated saves),
/// and thousands through the library (configs and scripts): counts how many were handled
/// cleanly. Every one must be.
#[test]
fn hostile_input_sweep() {
    let dir = case_dir("sweep");
    let good = dir.join("good.planet");
    write_save(&good, 2);
    let out = dir.join("out");
    let mut inputs: Vec<(String, Input, f64, f64)> = Vec::new();
    let small = ["--samples", "1000", "--plates", "6", "--quiet", "--my", "0"];
    // Every flag of generate with hostile values (a 1,000-sample planet and no steps unless
    // the flag itself asks for some).
    for (flag, values) in flag_values() {
        for v in values {
            let mut a: Vec<OsString> = vec!["generate".into()];
            if flag == "--my" || flag == "--samples" || flag == "--plates" {
                a.extend(["--quiet".into(), "--width".into(), "16".into()]);
                if flag != "--samples" {
                    a.extend(["--samples".into(), "1000".into()]);
                }
                if flag != "--plates" {
                    a.extend(["--plates".into(), "6".into()]);
                }
                if flag != "--my" {
                    a.extend(["--my".into(), "0".into()]);
                }
            } else {
                a.extend(small.iter().map(OsString::from));
                if flag != "--width" {
                    a.extend(["--width".into(), "16".into()]);
                }
            }
            a.push(format!("{flag}={v}").into());
            a.extend(["--out".into(), os(&out)]);
            let label = format!("generate {flag}={}", v.chars().take(20).collect::<String>());
            // A flag that asks for many samples or steps may run for a while, within the caps.
            inputs.push((
                label,
                Input {
                    args: a,
                    ..Default::default()
                },
                60.0,
                2_000.0,
            ));
        }
    }
    // Export flags on a good save.
    for (flag, values) in export_values() {
        for v in values {
            let mut a: Vec<OsString> = vec!["export".into(), os(&good), "--no-maps".into()];
            a.extend(
                [
                    "--amplified",
                    "--geotiff",
                    "--gltf",
                    "--gltf-segments",
                    "16",
                ]
                .map(OsString::from),
            );
            if flag != "--resolution" && flag != "--region" && flag != "--amplified-width" {
                a.extend(["--amplified-width".into(), "32".into()]);
            }
            if flag == "--resolution" {
                a.extend(["--region".into(), "0,0,0.5,0.5".into()]);
            }
            if flag == "--region" {
                a.extend(["--resolution".into(), "20km".into()]);
            }
            a.push(format!("{flag}={v}").into());
            a.extend(["--out".into(), os(&out)]);
            inputs.push((
                format!("export {flag}={v}"),
                Input {
                    args: a,
                    ..Default::default()
                },
                30.0,
                1_000.0,
            ));
        }
    }
    // Every kind of special file wherever a file is named. Outputs (--save, --out) only in the
    // sweep's folder: a regression must not write into / or replace /dev/null. Configs and
    // scripts are read from pipes as given (`--config <(...)`), so a FIFO nobody writes is
    // left out there (row G feeds one).
    for (name, p) in special_paths(&dir) {
        let local = p.starts_with(&dir);
        let fifo = name.contains("fifo");
        let generate = |tail: &[&str]| -> Vec<OsString> {
            [
                "generate",
                "--samples",
                "1000",
                "--plates",
                "6",
                "--quiet",
                "--width",
                "16",
            ]
            .iter()
            .chain(tail)
            .map(OsString::from)
            .collect()
        };
        let mut places: Vec<Vec<OsString>> = vec![
            vec!["resume".into(), os(&p), "--my".into(), "1".into()],
            vec!["export".into(), os(&p), "--out".into(), os(&out)],
        ];
        if !fifo {
            let mut c = generate(&["--my", "0", "--config"]);
            c.extend([os(&p), "--out".into(), os(&out)]);
            places.push(c);
            let mut c = generate(&["--my", "2", "--script"]);
            c.extend([os(&p), "--out".into(), os(&out)]);
            places.push(c);
            places.push(vec!["params".into(), "--config".into(), os(&p)]);
        }
        if local {
            let mut c = generate(&["--my", "0", "--save"]);
            c.extend([os(&p), "--out".into(), os(&out)]);
            places.push(c);
            let mut c = generate(&["--my", "0", "--out"]);
            c.push(os(&p));
            places.push(c);
        }
        places.push(vec![
            "export".into(),
            os(&good),
            "--no-maps".into(),
            "--amplified".into(),
            "--amplified-width".into(),
            "32".into(),
            "--exemplars".into(),
            os(&p),
            "--out".into(),
            os(&out),
        ]);
        for a in places {
            let label = format!("{} {name}", a[0].to_string_lossy());
            inputs.push((
                label,
                Input {
                    args: a,
                    ..Default::default()
                },
                10.0,
                500.0,
            ));
        }
    }
    // Mutated saves through `export` (the library's property test in tests/saves.rs tries
    // thousands in-process; these go through the file reader too).
    let bytes = std::fs::read(&good).unwrap();
    let mut rng = tectonic_planets::random::SimRng::new(16, 16);
    for k in 0..60 {
        let mut b = bytes.clone();
        let i = (rng.next_u64() as usize) % b.len();
        match k % 4 {
            0 => b[i] ^= 0x40,
            1 => b.truncate(i),
            2 => b[i..(i + 8).min(bytes.len())].fill(0xFF),
            _ => b.extend_from_slice(&bytes[..i.min(64)]),
        }
        if k % 2 == 0 && b.len() >= save::HEADER_LEN {
            let body = (b.len() - save::HEADER_LEN) as u64;
            b[16..24].copy_from_slice(&body.to_le_bytes());
            let crc = save::checksum(&b);
            b[24..28].copy_from_slice(&crc.to_le_bytes());
        }
        let p = dir.join(format!("mutant{k}.planet"));
        std::fs::write(&p, &b).unwrap();
        inputs.push((
            format!("export mutant {k}"),
            Input {
                args: vec![
                    "export".into(),
                    os(&p),
                    "--width".into(),
                    "16".into(),
                    "--out".into(),
                    os(&out),
                ],
                ..Default::default()
            },
            10.0,
            500.0,
        ));
    }
    let cli_total = inputs.len();
    // Two at a time (the bounds are loose enough for a shared machine).
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some((label, input, max_s, max_mb)) = inputs.get(k) else {
                        break;
                    };
                    let run = run_planet(input, &dir, Duration::from_secs_f64(max_s * 2.0));
                    let r = clean(&run, *max_s, *max_mb)
                        .map(|()| (label.clone(), run.code))
                        .map_err(|why| format!("{label}: {why}"));
                    results.lock().unwrap().push(r);
                }
            });
        }
    });
    let results = results.into_inner().unwrap();
    let cli_clean = results.iter().filter(|r| r.is_ok()).count();
    let by_code = |c: i32| {
        results
            .iter()
            .filter(|r| r.as_ref().is_ok_and(|(_, code)| *code == Some(c)))
            .count()
    };
    println!(
        "binary: {} refused with an error (exit 1), {} refused by the argument parser (exit 2), {} accepted (exit 0):",
        by_code(1),
        by_code(2),
        by_code(0)
    );
    for (label, _) in results.iter().flatten().filter(|(_, c)| *c == Some(0)) {
        println!("  accepted: {label}");
    }
    let mut bad: Vec<String> = results.into_iter().filter_map(|r| r.err()).collect();
    // Whatever happened, the good save and the FIFO are intact.
    assert!(is_fifo(&dir.join("sweep.fifo")), "the FIFO was replaced");
    assert_eq!(save_step(&good), 2, "the good save was damaged");
    // In-process: configs (every key with hostile values) and scripts (every command with
    // hostile values). An error must be bounded and name the key or event; nothing panics.
    let (lib_total, lib_clean, lib_bad) = library_sweep();
    bad.extend(lib_bad);
    println!(
        "hostile sweep: {} inputs tried, {} handled cleanly ({cli_total} through the binary: {cli_clean} clean; {lib_total} configs and scripts through the library: {lib_clean} clean)",
        cli_total + lib_total,
        cli_clean + lib_clean
    );
    assert!(bad.is_empty(), "not handled cleanly:\n{}", bad.join("\n"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Configs and scripts with hostile values, parsed by the library: (tried, clean, failures).
fn library_sweep() -> (usize, usize, Vec<String>) {
    use tectonic_planets::commands::Script;
    let values = [
        "nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "1e308",
        "-1e308",
        "1e-320",
        "\"text\"",
        "true",
        "[1, 2]",
        "{ a = 1 }",
        "18446744073709551615",
        "9223372036854775808",
        "1979-05-27",
        "\"\\u0000\"",
    ];
    let mut total = 0;
    let mut clean = 0;
    let mut bad = Vec::new();
    let mut check = |label: String, r: std::thread::Result<Result<(), String>>| {
        total += 1;
        match r {
            Err(_) => bad.push(format!("{label}: panicked")),
            Ok(Err(msg)) if msg.len() > 4_000 || msg.is_empty() => {
                bad.push(format!("{label}: message of {} bytes", msg.len()))
            }
            Ok(_) => clean += 1,
        }
    };
    for spec in Params::schema() {
        for v in values {
            let text = format!("[{}]\n{} = {v}\n", spec.section, spec.name);
            let r = std::panic::catch_unwind(|| {
                Params::from_toml_str(&text)
                    .map(|_| ())
                    .map_err(|e| e.to_string())
            });
            check(format!("config {} = {v}", spec.key), r);
        }
    }
    let commands = [
        "command = \"set_motion\"\nplate = {p}\npole = {{ lat = {v}, lon = 0 }}\nspeed_mm_per_yr = {v}",
        "command = \"set_crust_type\"\ncap = {{ lat = {v}, lon = {v}, radius_km = {v} }}\ncrust = \"oceanic\"",
        "command = \"rift_line\"\nline = [{{ lat = {v}, lon = 0 }}, {{ lat = 0, lon = {v} }}]",
        "command = \"rift_at\"\nplate = {p}\nfragments = {v}",
        "command = \"uplift\"\ncap = {{ lat = 0, lon = 0, radius_km = {v} }}\ndelta_km = {v}",
        "command = \"set_phenomenon\"\nname = {v}\nenabled = {v}",
        "command = \"set_param\"\nkey = \"ocean.damping_mm_per_yr\"\nvalue = {v}",
    ];
    let params = Params::default();
    for c in commands {
        for v in values {
            for p in ["0", "4294967296", "-1", "{ lat = 95, lon = 0 }"] {
                let body = c
                    .replace("{v}", v)
                    .replace("{p}", p)
                    .replace("{{", "{")
                    .replace("}}", "}");
                for at in ["0", "-1", "nan", "1e300"] {
                    let text = format!("[[event]]\nat_my = {at}\n{body}\n");
                    let r = std::panic::catch_unwind(|| {
                        Script::parse(&text, "sweep.toml")
                            .map_err(|e| e.to_string())
                            .and_then(|s| s.validate(&params).map_err(|e| e.to_string()))
                    });
                    check(format!("script {body:?} at {at}"), r);
                }
            }
        }
    }
    (total, clean, bad)
}
