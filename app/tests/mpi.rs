//! `--mpi` under a real `mpirun` (OpenMPI): images and depth maps of 2 and 3 ranks equal
//! the single-process ones byte for byte, for a grid, a mesh, a time step of a series and an
//! `.isot`; a movie likewise; `bench --mpi` reports every rank; a rank that cannot open
//! its input ends the job with an error naming it, within seconds.
//!
//! Needs `mpirun` on the PATH (`.ci/run` installs OpenMPI); built only with feature `mpi`.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_isoscope");

/// Runs `cmd`, killing it after `limit` (a hang is a failure, not a stuck CI).
fn run_limited(mut cmd: Command, limit: Duration) -> Output {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mpirun starts (is OpenMPI installed?)");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            child.kill().unwrap();
            panic!("{cmd:?} did not end within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn mpirun(dir: &Path, ranks: usize, args: &[&str]) -> Output {
    let mut cmd = Command::new("mpirun");
    cmd.current_dir(dir)
        .args(["--allow-run-as-root", "--oversubscribe", "-n"])
        .arg(ranks.to_string())
        .arg(BIN)
        .args(args)
        .arg("--mpi")
        .env("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
        .env("RAYON_NUM_THREADS", "1");
    run_limited(cmd, Duration::from_mins(2))
}

/// Two ranks, each running the shell `script` (which tells the ranks apart by
/// `$OMPI_COMM_WORLD_RANK`), limited to a minute.
fn mpirun_sh(dir: &Path, script: &str) -> Output {
    let mut cmd = Command::new("mpirun");
    cmd.current_dir(dir)
        .args([
            "--allow-run-as-root",
            "--oversubscribe",
            "-n",
            "2",
            "sh",
            "-c",
        ])
        .arg(script);
    run_limited(cmd, Duration::from_mins(1))
}

fn isoscope(dir: &Path, args: &[&str]) -> Output {
    let out = Command::new(BIN)
        .current_dir(dir)
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .unwrap();
    assert!(out.status.success(), "{args:?}: {}", text(&out));
    out
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn same_files(dir: &Path, a: &str, b: &str) {
    let (x, y) = (
        std::fs::read(dir.join(a)).unwrap(),
        std::fs::read(dir.join(b)).unwrap(),
    );
    assert!(x == y, "{a} and {b} differ");
}

/// Renders `input` (with `extra` flags) in one process and under mpirun with 2 and 3
/// ranks; the PNGs and depth maps must be identical.
fn renders_identically(dir: &Path, input: &str, extra: &[&str]) {
    let mut args = vec!["render", input, "--size", "180x140", "--force"];
    args.extend_from_slice(extra);
    let one = [&args[..], &["-o", "one.png", "--depth-out", "one.npy"]].concat();
    isoscope(dir, &one);
    for ranks in [2, 3] {
        let many = [&args[..], &["-o", "many.png", "--depth-out", "many.npy"]].concat();
        let out = mpirun(dir, ranks, &many);
        assert!(
            out.status.success(),
            "{input} on {ranks} ranks: {}",
            text(&out)
        );
        same_files(dir, "one.png", "many.png");
        same_files(dir, "one.npy", "many.npy");
    }
}

fn generate(dir: &Path, args: &[&str]) {
    isoscope(dir, &[&["generate"], args].concat());
}

#[test]
fn grids_meshes_series_steps_and_isot_files_render_as_in_one_process() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    generate(d, &["phantom", "--size", "64", "-o", "ph.nrrd"]);
    renders_identically(d, "ph.nrrd", &["--iso", "500", "--shadows"]);
    generate(d, &["tet-ball", "--tets", "20000", "-o", "ball.vtu"]);
    renders_identically(
        d,
        "ball.vtu",
        &[
            "--iso",
            "0.5",
            "--iso",
            "0.3:#4080ff:0.4",
            "--normals",
            "smooth",
        ],
    );
    generate(
        d,
        &["blobs", "--steps", "3", "--size", "32", "-o", "bl.nrrd"],
    );
    renders_identically(d, "bl_%03d.nrrd", &["--step", "2"]);
    isoscope(d, &["preprocess", "ph.nrrd", "-o", "ph.isot"]);
    renders_identically(d, "ph.isot", &["--iso", "500", "--normals", "faceted"]);
}

#[test]
fn a_movie_and_a_benchmark_run_across_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    generate(d, &["phantom", "--size", "48", "-o", "ph.nrrd"]);
    let movie = |out: &str| {
        vec![
            "movie", "ph.nrrd", "--iso", "500", "--frames", "3", "--size", "96x64", "-o", out,
        ]
        .into_iter()
        .map(str::to_string)
        .collect::<Vec<_>>()
    };
    let one: Vec<String> = movie("one");
    isoscope(d, &one.iter().map(String::as_str).collect::<Vec<_>>());
    let many = movie("many");
    let out = mpirun(d, 2, &many.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.status.success(), "{}", text(&out));
    let frames = |sub: &str| {
        let mut v: Vec<_> = std::fs::read_dir(d.join(sub))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "png"))
            .collect();
        v.sort();
        v
    };
    let (a, b) = (frames("one"), frames("many"));
    assert_eq!(a.len(), 3);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert!(
            std::fs::read(x).unwrap() == std::fs::read(y).unwrap(),
            "{x:?} vs {y:?}"
        );
    }

    let out = mpirun(
        d,
        3,
        &[
            "bench", "ph.nrrd", "--iso", "500", "--size", "256x256", "--frames", "2", "--json",
        ],
    );
    assert!(out.status.success(), "{}", text(&out));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["ranks"], 3);
    let ranks = report["per_rank"].as_array().unwrap();
    assert_eq!(ranks.len(), 3);
    // Every chunk of the 256x256 frame (4x4 chunks of 64x64) was rendered by some rank.
    let chunks: f64 = ranks
        .iter()
        .map(|r| r["chunks_per_frame"].as_f64().unwrap())
        .sum();
    assert_eq!(chunks, 16.0);
    assert!(report["gather_bytes_per_frame"].as_f64().unwrap() > 0.0);
}

#[test]
fn a_rank_that_cannot_open_its_input_ends_the_job_with_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    generate(d, &["phantom", "--size", "32", "-o", "ph.nrrd"]);
    std::fs::create_dir(d.join("elsewhere")).unwrap();
    // Rank 1 starts in a folder without the file, as a node without the shared storage.
    let start = Instant::now();
    let out = mpirun_sh(
        d,
        &format!(
            "if [ \"$OMPI_COMM_WORLD_RANK\" = 1 ]; then cd elsewhere; fi; exec {BIN} render \
             ph.nrrd -o out.png --size 64x64 --mpi"
        ),
    );
    assert!(!out.status.success());
    assert!(start.elapsed() < Duration::from_secs(30));
    let t = text(&out);
    assert!(t.contains("Error: rank 1: ph.nrrd: No such file"), "{t}");
    assert!(!d.join("out.png").exists(), "no image from a failed job");
}

#[test]
fn a_rank_that_dies_mid_job_ends_it_with_an_error_instead_of_a_hang() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    generate(d, &["phantom", "--size", "64", "-o", "ph.nrrd"]);
    // Rank 1's isoscope is killed once the job is under way; rank 0 benchmarks many frames
    // and must stop, by MPI noticing the death or by --mpi-timeout, naming the failure.
    let start = Instant::now();
    let out = mpirun_sh(
        d,
        &format!(
            "args='bench ph.nrrd --iso 500 --size 512x512 --frames 100000 --skip-dda --mpi \
             --mpi-timeout 3'; if [ \"$OMPI_COMM_WORLD_RANK\" = 1 ]; then {BIN} $args & \
             pid=$!; sleep 2; kill -9 $pid; wait $pid; exit 9; else exec {BIN} $args; fi"
        ),
    );
    assert!(!out.status.success());
    assert!(start.elapsed() < Duration::from_secs(40));
    // Either our timeout names the rank, or OpenMPI ends the job first, naming the process
    // of rank 1 as `[[JOB,1],1]`.
    let t = text(&out);
    assert!(
        t.contains("rank 1 sent no tile results") || t.contains(",1],1]"),
        "{t}"
    );
}

#[test]
fn traversal_statistics_are_refused_with_mpi_rather_than_partial() {
    let dir = tempfile::tempdir().unwrap();
    generate(dir.path(), &["phantom", "--size", "32", "-o", "ph.nrrd"]);
    let out = Command::new(BIN)
        .current_dir(dir.path())
        .args(["render", "ph.nrrd", "-o", "o.png", "--stats", "--mpi"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(text(&out).contains("--stats counts the traversal of one process"));
    assert!(!dir.path().join("o.png").exists());
}
