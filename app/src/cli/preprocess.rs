//! `isoscope preprocess IN -o OUT.isot [--treelet-height 9] [--levels auto]`: builds the
//! out-of-core treelet file (thesis seed 004 §7.8.1; format in `docs/treelet-format.md`).
//!
//! The input is opened like every other command (`formats::open`, memory-mapped) and never
//! written; the output is written to a temporary name next to it and renamed when complete.
//! The build streams (see `volume_core::ooc::build`): memory stays bounded for inputs
//! larger than RAM. A progress bar counts MB read over the two passes with the current
//! throughput; the summary reports input throughput and the peak anonymous memory.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use formats::output::Replace;
use volume_core::ooc::TreeletLayout;

use super::open_args::OpenArgs;
use crate::progress::Progress;

/// Arguments of `isoscope preprocess`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input volume (.nrrd/.nhdr, .nii/.nii.gz, .hdr/.img, or raw with the raw flags or a
    /// NAME.json sidecar).
    pub input: PathBuf,
    /// Output treelet file (.isot).
    #[arg(short, long, value_name = "OUT.isot")]
    pub output: PathBuf,
    /// Replace an existing output file (never an input file).
    #[arg(long)]
    pub force: bool,
    /// Node levels per treelet (the thesis found 9 best).
    #[arg(long, default_value_t = 9, value_parser = clap::value_parser!(u32).range(1..=24))]
    pub treelet_height: u32,
    /// Number of LOD/treelet levels: `auto` (from --treelet-height) or a count, which
    /// overrides the height.
    #[arg(long, default_value = "auto", value_parser = parse_levels)]
    pub levels: Levels,
    #[command(flatten)]
    pub open: OpenArgs,
}

/// `--levels`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Levels {
    Auto,
    Count(usize),
}

/// Parses `auto` or a positive level count.
pub fn parse_levels(s: &str) -> Result<Levels, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(Levels::Auto);
    }
    match s.parse::<usize>() {
        Ok(n) if (1..=64).contains(&n) => Ok(Levels::Count(n)),
        _ => Err(format!(
            "expected `auto` or a level count 1..=64, got `{s}`"
        )),
    }
}

/// What [`build`] wrote.
#[derive(Debug, Clone, Copy)]
pub struct Built {
    pub treelets: u64,
    pub levels: usize,
    pub treelet_height: u32,
    /// Bytes of the input volume's voxels (one pass).
    pub input_bytes: u64,
}

/// Opens the input, checks the output and writes the `.isot` file; `progress(done, total)`
/// counts voxel bytes read over the two passes (`total` = twice the input). The one
/// preprocess path of the CLI and the Python package.
pub fn build(args: &Args, progress: &mut dyn FnMut(u64, u64)) -> anyhow::Result<Built> {
    let replace = Replace::from_force(args.force);
    let options = args.open.open_options()?;
    let dataset = formats::open(&args.input, &options)
        .with_context(|| format!("opening {}", args.input.display()))?;
    // After the open, which recorded every file the input reads: fail before the long build.
    formats::output::check_output(&args.output, replace)?;
    if dataset.time_steps() > 1 {
        eprintln!(
            "note: {} has {} time steps; preprocessing the first",
            args.input.display(),
            dataset.time_steps()
        );
    }
    let volume = dataset.first_volume();
    // The tree splits as the in-core tree does, along its nodes' longest world axis.
    let layout = match args.levels {
        Levels::Auto => TreeletLayout::for_grid(&volume.grid, args.treelet_height),
        Levels::Count(n) => TreeletLayout::for_grid_with_levels(&volume.grid, n),
    }
    .with_context(|| format!("{}: cannot cut into treelets", args.input.display()))?;
    let levels = layout.level_count();
    let treelet_height = layout.treelet_height();
    let input_bytes = volume.data.size_bytes() as u64;
    // The build reads the input twice (pass 1: value range + streamed LOD pyramid; pass 2:
    // finest treelets).
    let voxel_bytes = volume.data.voxel_type().size_bytes() as u64;
    let report = formats::treelet::write_isot_volume(
        &args.output,
        volume,
        layout,
        replace,
        &mut |done, total| progress(done * voxel_bytes, total * voxel_bytes),
    )?;
    Ok(Built {
        treelets: report.treelets,
        levels,
        treelet_height,
        input_bytes,
    })
}

pub fn run(args: &Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let mut meter = Meter::new(start);
    let mut bar = None;
    let built = build(args, &mut |done, total| {
        // The bar counts MB read over both passes.
        let bar = bar.get_or_insert_with(|| Progress::bar(total.div_ceil(1 << 20), "preprocess"));
        bar.inc((done >> 20).saturating_sub(bar.position()));
        if let Some(msg) = meter.tick(done, total / 2) {
            bar.set_message(msg);
        }
    })?;
    if let Some(bar) = bar {
        bar.finish();
    }
    meter.sample_memory();
    let secs = start.elapsed().as_secs_f64().max(1e-9);
    let out_bytes = std::fs::metadata(&args.output).map_or(0, |m| m.len());
    println!(
        "{}: {} treelets in {} levels (height {}), {:.1} MB written, {:.2} s, \
         {:.1} MB/s input, peak anonymous memory {:.1} MB (sampled)",
        args.output.display(),
        built.treelets,
        built.levels,
        built.treelet_height,
        out_bytes as f64 / 1e6,
        secs,
        built.input_bytes as f64 / 1e6 / secs,
        meter.peak_anon_bytes as f64 / 1e6,
    );
    Ok(())
}

/// Throughput and memory for the progress message, refreshed at most twice a second.
struct Meter {
    start: Instant,
    last: Instant,
    peak_anon_bytes: u64,
}

impl Meter {
    fn new(start: Instant) -> Self {
        let mut m = Self {
            start,
            last: start,
            peak_anon_bytes: 0,
        };
        m.sample_memory();
        m
    }

    /// Anonymous resident memory (`RssAnon` of `/proc/self/status`, Linux): what the build
    /// itself holds, without the input and output file pages the kernel can drop.
    fn sample_memory(&mut self) {
        let anon = std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find_map(|l| l.strip_prefix("RssAnon:"))
                    .and_then(|r| r.split_whitespace().next()?.parse::<u64>().ok())
            })
            .map_or(0, |kb| kb * 1024);
        self.peak_anon_bytes = self.peak_anon_bytes.max(anon);
    }

    /// `read` bytes of `2 × input` so far: a message when it is time for a new one.
    fn tick(&mut self, read: u64, input: u64) -> Option<String> {
        let now = Instant::now();
        if now.duration_since(self.last).as_secs_f64() < 0.5 {
            return None;
        }
        self.last = now;
        self.sample_memory();
        let secs = now.duration_since(self.start).as_secs_f64().max(1e-9);
        let pass = if read < input {
            "1/2 range+LOD"
        } else {
            "2/2 treelets"
        };
        Some(format!(
            "preprocess pass {pass}: {:.0} MB/s input (both passes), {:.0} MB anon",
            read as f64 / 2.0 / 1e6 / secs,
            self.peak_anon_bytes as f64 / 1e6
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse() {
        assert_eq!(parse_levels("auto"), Ok(Levels::Auto));
        assert_eq!(parse_levels("AUTO"), Ok(Levels::Auto));
        assert_eq!(parse_levels("3"), Ok(Levels::Count(3)));
        assert!(parse_levels("0").is_err());
        assert!(parse_levels("x").is_err());
    }

    #[test]
    fn preprocess_writes_a_valid_file_and_refuses_to_overwrite_the_input() {
        use volume_core::{Grid, RectilinearVolume};
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.nrrd");
        let g = Grid::uniform([9, 8, 7], [0.0; 3], [1.0; 3]).unwrap();
        let voxels: Vec<u8> = (0..9 * 8 * 7).map(|i| (i * 7 % 256) as u8).collect();
        let v = RectilinearVolume::new(g, voxels.into()).unwrap();
        formats::nrrd::write_nrrd(
            &input,
            &v,
            formats::nrrd::NrrdEncoding::Raw,
            Replace::Refuse,
        )
        .unwrap();
        let before = std::fs::read(&input).unwrap();
        let output = dir.path().join("out.isot");
        let args = Args {
            input: input.clone(),
            output: output.clone(),
            treelet_height: 3,
            levels: Levels::Auto,
            open: OpenArgs::default(),
            force: false,
        };
        run(&args).unwrap();
        assert_eq!(std::fs::read(&input).unwrap(), before);
        // An existing output is replaced only with --force (checked before this process
        // opens the output: a file it has read is an input from then on).
        let e = run(&Args {
            levels: Levels::Count(2),
            ..args
        })
        .unwrap_err()
        .to_string();
        assert!(e.contains("already exists") && e.contains("--force"), "{e}");
        let forced = |output: &std::path::Path, levels| Args {
            input: input.clone(),
            output: output.to_path_buf(),
            treelet_height: 3,
            levels,
            open: OpenArgs::default(),
            force: true,
        };
        run(&forced(&output, Levels::Count(2))).unwrap();
        let f = formats::treelet::IsotFile::open(&output).unwrap();
        f.verify().unwrap();
        assert_eq!(f.plans().len(), 2);
        // Neither the input nor a file this process has read is ever an output.
        for target in [&input, &output] {
            let e = run(&forced(target, Levels::Auto)).unwrap_err().to_string();
            assert!(e.contains("is the input file"), "{e}");
        }
        assert_eq!(std::fs::read(&input).unwrap(), before);
    }
}
