//! The hostile corpus (`data_samples::hostile`) through the real binary: `isoscope info` and
//! `isoscope render --size 32x32` on every case.
//!
//! - A bad case must exit non-zero with an error that names one of its files, and never
//!   panic (no "panicked" in stderr, no death by a signal: an abort is a failure).
//! - A valid case must give exit 0 from both, and a 32×32 PNG.
//! - No run may take longer than [`TIMEOUT`] (the child is killed and the case fails) or
//!   allocate more than [`MEMORY_LIMIT_MIB`] (see [`isoscope_limited`]).
//!
//! The outcome table (reader × kind → clean errors, renders, failures) is printed and written
//! to `target/tmp/hostile-corpus.md`; `docs/reliability.md` ("Malformed-file corpus") is a
//! copy of it. Regenerate with
//! `cargo test -p isoscope --test cli_hostile_corpus -- --nocapture`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use data_samples::hostile::{Case, Expect, Kind, Reader, write_corpus};

/// Longest a single `info` or `render` may run. Debug-profile binaries on a loaded 2-core CI
/// machine open and render these tiny files in well under a second; a hang is caught here.
const TIMEOUT: Duration = Duration::from_secs(8);

/// Heap limit per child.
const MEMORY_LIMIT_MIB: u64 = 256;

/// Worker threads (CI has 2 cores; each child is mostly process start-up).
const WORKERS: usize = 2;

struct Run {
    /// `None`: killed after [`TIMEOUT`].
    status: Option<ExitStatus>,
    stderr: String,
    elapsed: Duration,
}

/// Runs `isoscope ARGS` under a memory limit, killed after [`TIMEOUT`].
///
/// The limit is `ulimit -d` (RLIMIT_DATA, which Linux ≥ 4.7 applies to every private
/// writable mapping: the heap, `mmap`ed allocations, thread stacks) rather than `ulimit -v`
/// (address space), because the address space of a 140 MB debug binary, its shared
/// libraries and read-only memory-mapped inputs says nothing about what a header made the
/// reader allocate. `MALLOC_ARENA_MAX=2` keeps glibc from reserving an arena per rayon
/// thread. An allocation beyond the limit fails, and Rust aborts the process: a signal
/// exit, reported as a failure of the case. Backtraces are off so stderr is what a user sees.
fn isoscope_limited(args: &[&str], logs: &Path) -> Run {
    let err_path = logs.join(format!(
        "stderr-{}",
        NEXT_LOG.fetch_add(1, Ordering::Relaxed)
    ));
    let err = std::fs::File::create(&err_path).expect("stderr log");
    let start = Instant::now();
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -d {} && exec \"$0\" \"$@\"",
            MEMORY_LIMIT_MIB * 1024
        ))
        .arg(env!("CARGO_BIN_EXE_isoscope"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .env("MALLOC_ARENA_MAX", "2")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .expect("run isoscope");
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break Some(s);
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let elapsed = start.elapsed();
    let stderr =
        String::from_utf8_lossy(&std::fs::read(&err_path).unwrap_or_default()).into_owned();
    let _ = std::fs::remove_file(&err_path);
    Run {
        status,
        stderr,
        elapsed,
    }
}

static NEXT_LOG: AtomicUsize = AtomicUsize::new(0);

#[derive(Default, Clone, Copy)]
struct Tally {
    errors: usize,
    renders: usize,
    failures: usize,
    slowest: Duration,
}

/// Checks one run of a bad case; `Err` says what was wrong.
fn check_error(case: &Case, what: &str, run: &Run) -> Result<(), String> {
    let Some(status) = run.status else {
        return Err(format!("{what}: no answer within {TIMEOUT:?} (killed)"));
    };
    if status.success() {
        return Err(format!("{what}: exit 0 for a bad file"));
    }
    if status.code().is_none() {
        return Err(format!(
            "{what}: killed by a signal ({status}): {}",
            tail(&run.stderr)
        ));
    }
    if run.stderr.contains("panicked") {
        return Err(format!("{what}: panicked: {}", tail(&run.stderr)));
    }
    if !case.names.iter().any(|n| run.stderr.contains(n.as_str())) {
        return Err(format!(
            "{what}: the error names none of {:?}: {}",
            case.names,
            tail(&run.stderr)
        ));
    }
    Ok(())
}

fn check_ok(what: &str, run: &Run) -> Result<(), String> {
    match run.status {
        None => Err(format!("{what}: no answer within {TIMEOUT:?} (killed)")),
        Some(s) if !s.success() => Err(format!("{what}: {s}: {}", tail(&run.stderr))),
        Some(_) if run.stderr.contains("panicked") => {
            Err(format!("{what}: panicked: {}", tail(&run.stderr)))
        }
        Some(_) => Ok(()),
    }
}

fn tail(s: &str) -> String {
    let s = s.trim();
    let start = s.len().saturating_sub(400);
    let start = (start..=s.len())
        .find(|&i| s.is_char_boundary(i))
        .unwrap_or(0);
    s[start..].to_string()
}

/// Runs `info` and `render` on `case`; returns (problems, slowest run).
fn run_case(case: &Case, out_dir: &Path, logs: &Path) -> (Vec<String>, Duration) {
    let file = case.open.to_str().expect("UTF-8 temp path");
    let png = out_dir.join(format!("{}.png", case.name));
    let png_s = png.to_str().expect("UTF-8 temp path");
    let info = isoscope_limited(&["info", file], logs);
    let step = case.bad_step.map(|s| s.to_string());
    let mut args = vec!["render", file, "--size", "32x32", "-o", png_s];
    if let Some(s) = &step {
        args.extend(["--step", s.as_str()]);
    }
    args.extend(case.render_args.iter().map(String::as_str));
    let render = isoscope_limited(&args, logs);
    let slowest = info.elapsed.max(render.elapsed);
    let mut problems = Vec::new();
    match case.expect {
        Expect::Error => {
            for (what, run) in [("info", &info), ("render", &render)] {
                if let Err(e) = check_error(case, what, run) {
                    problems.push(e);
                }
            }
            if png.exists() {
                problems.push("render left an output for a bad file".into());
            }
        }
        Expect::Renders => {
            for (what, run) in [("info", &info), ("render", &render)] {
                if let Err(e) = check_ok(what, run) {
                    problems.push(e);
                }
            }
            if render.status.is_some_and(|s| s.success()) {
                match image::open(&png) {
                    Ok(img) if (img.width(), img.height()) == (32, 32) => {}
                    Ok(img) => problems.push(format!(
                        "render wrote a {}x{} image, not 32x32",
                        img.width(),
                        img.height()
                    )),
                    Err(e) => problems.push(format!("render output unreadable: {e}")),
                }
            }
        }
    }
    (problems, slowest)
}

/// The markdown outcome table.
fn table(results: &BTreeMap<(Reader, Kind), Tally>, cases: usize, wall: Duration) -> String {
    let mut s = String::from(
        "| Reader | Kind | Cases | Clean error | Renders | Failures | Slowest run |\n| --- | --- | ---: | ---: | ---: | ---: | ---: |\n",
    );
    let mut total = Tally::default();
    for r in Reader::ALL {
        for k in Kind::ALL {
            let Some(t) = results.get(&(r, k)) else {
                continue;
            };
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} | {} | {} ms |",
                r.name(),
                k.name(),
                t.errors + t.renders + t.failures,
                t.errors,
                t.renders,
                t.failures,
                t.slowest.as_millis()
            );
            total.errors += t.errors;
            total.renders += t.renders;
            total.failures += t.failures;
            total.slowest = total.slowest.max(t.slowest);
        }
    }
    let _ = writeln!(
        s,
        "| **all** | | **{cases}** | **{}** | **{}** | **{}** | {} ms |\n\n{} runs (`info` and `render` per case) in {:.0} s with {WORKERS} workers.",
        total.errors,
        total.renders,
        total.failures,
        total.slowest.as_millis(),
        2 * cases,
        wall.as_secs_f64()
    );
    s
}

#[cfg(unix)]
#[test]
fn every_corpus_file_gives_a_clean_error_or_renders() {
    let dir = tempfile::tempdir().unwrap();
    let corpus = dir.path().join("corpus");
    let out = dir.path().join("out");
    let logs = dir.path().join("logs");
    for d in [&corpus, &out, &logs] {
        std::fs::create_dir(d).unwrap();
    }
    let cases = write_corpus(&corpus).unwrap();
    assert!(cases.len() >= 300, "{} cases", cases.len());

    let start = Instant::now();
    let next = AtomicUsize::new(0);
    let results: Mutex<BTreeMap<(Reader, Kind), Tally>> = Mutex::new(BTreeMap::new());
    let failures: Mutex<Vec<String>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..WORKERS {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(case) = cases.get(i) else { break };
                    let (problems, slowest) = run_case(case, &out, &logs);
                    let mut r = results.lock().unwrap();
                    let t = r.entry((case.reader, case.kind)).or_default();
                    t.slowest = t.slowest.max(slowest);
                    if !problems.is_empty() {
                        t.failures += 1;
                        failures.lock().unwrap().push(format!(
                            "{}: {}",
                            case.name,
                            problems.join("; ")
                        ));
                    } else if case.expect == Expect::Renders {
                        t.renders += 1;
                    } else {
                        t.errors += 1;
                    }
                }
            });
        }
    });
    let wall = start.elapsed();
    let results = results.into_inner().unwrap();
    let md = table(&results, cases.len(), wall);
    println!("{md}");
    let report = Path::new(env!("CARGO_TARGET_TMPDIR")).join("hostile-corpus.md");
    let _ = std::fs::write(&report, &md);
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
    // Every case was run and counted once.
    let counted: usize = results
        .values()
        .map(|t| t.errors + t.renders + t.failures)
        .sum();
    assert_eq!(counted, cases.len());
}
