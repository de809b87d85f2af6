//! The `isoscope preprocess` pipeline without the app crate (no GUI build), for profiling the
//! out-of-core build (thesis seed 004 §7.8.1):
//!
//! ```text
//! isot_preprocess gen-blobs 512x512x256 u8 ooc/blobs_u8.nrrd   # dense Gaussian blobs
//! isot_preprocess gen-sparse 1024x1024x256 ooc sparse          # sparse cone blobs (.nhdr)
//! isot_preprocess build IN OUT.isot [HEIGHT]                    # formats::open + write_isot_volume
//! ```
//!
//! `build` opens the input like the CLI (memory-mapped) and writes the same `.isot` as
//! `isoscope preprocess IN -o OUT.isot --treelet-height HEIGHT`; it prints the wall time and
//! the input throughput. Run it under `/usr/bin/time` for CPU time, or under
//! `valgrind --tool=callgrind` with `RAYON_NUM_THREADS=1` for instruction counts.

use std::path::Path;
use std::time::Instant;

use data_samples::blobs::Blobs;
use data_samples::sparse_blobs::{Blob, write_sparse_nrrd};
use volume_core::VoxelType;
use volume_core::ooc::TreeletLayout;

fn dims_arg(s: &str) -> [usize; 3] {
    let v: Vec<usize> = s
        .split('x')
        .map(|d| d.parse().expect("dims like 512x512x256"))
        .collect();
    v.try_into().expect("three dims")
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: isot_preprocess gen-blobs DIMS TYPE OUT.nrrd | gen-sparse DIMS DIR NAME | build IN OUT.isot [HEIGHT]";
    match args.first().map(String::as_str) {
        Some("gen-blobs") if args.len() == 4 => {
            let t = VoxelType::from_name(&args[2]).expect("voxel type name, e.g. u8");
            let v = Blobs::new(dims_arg(&args[1]), t, 1)
                .and_then(|b| b.step(0, &|| {}))
                .expect("blobs");
            formats::nrrd::write_nrrd(
                Path::new(&args[3]),
                &v,
                formats::nrrd::NrrdEncoding::Raw,
                formats::output::Replace::Refuse,
            )
            .expect("write nrrd");
        }
        Some("gen-sparse") if args.len() == 4 => {
            let d = dims_arg(&args[1]).map(|x| x as u64);
            // Three cones scaled to the volume, like the 2048×2048×1100 test's.
            let f = |x: f64, a: usize| x * d[a] as f64;
            let blobs = [
                Blob {
                    center: [f(0.07, 0), f(0.1, 1), f(0.11, 2)],
                    radius: f(0.05, 0),
                },
                Blob {
                    center: [f(0.5, 0), f(0.44, 1), f(0.5, 2)],
                    radius: f(0.07, 0),
                },
                Blob {
                    center: [f(0.93, 0), f(0.9, 1), f(0.94, 2)],
                    radius: f(0.03, 0),
                },
            ];
            let h = write_sparse_nrrd(Path::new(&args[2]), &args[3], d, &blobs).expect("sparse");
            println!("{}", h.display());
        }
        Some("build") if (3..=4).contains(&args.len()) => {
            let height = args.get(3).map_or(9, |h| h.parse().expect("height"));
            let input = Path::new(&args[1]);
            let dataset =
                formats::open(input, &formats::OpenOptions::default()).expect("open input");
            let volume = dataset.first_volume();
            let dims = volume.dims().map(|d| d as u64);
            let layout = TreeletLayout::for_grid(&volume.grid, height).expect("layout");
            let start = Instant::now();
            let report = formats::treelet::write_isot_volume(
                Path::new(&args[2]),
                volume,
                layout,
                formats::output::Replace::Allow,
                &mut |_, _| {},
            )
            .expect("build");
            let secs = start.elapsed().as_secs_f64();
            let mb = volume.data.size_bytes() as f64 / 1e6;
            println!(
                "{}: {dims:?} {}, {} treelets, {:.1} MB of records, {secs:.3} s, {:.1} MB/s input",
                args[2],
                volume.data.voxel_type().name(),
                report.treelets,
                report.bytes as f64 / 1e6,
                mb / secs
            );
        }
        _ => {
            eprintln!("{usage}");
            std::process::exit(2);
        }
    }
}
