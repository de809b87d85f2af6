//! Opening a 4 GB raw file reads nothing and does not grow resident
//! memory — the voxels are viewed in place in a memory map.
//!
//! The file is sparse (`File::set_len`), so it costs no disk space. This is a property test
//! (memory and "no read"), not a speed benchmark: the time bound is generous and only guards
//! against an accidental full read, which would take many seconds and gigabytes.

use std::fs::File;
use std::time::Instant;

use formats::raw::{Endian, RawLayout, read_raw};
use formats::{Dataset, OpenOptions};
use volume_core::{VoxelData, VoxelType};

/// Resident set size of this process in kB (Linux).
fn vm_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

#[test]
fn opening_a_4gb_raw_file_maps_it_without_reading() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("big.raw");
    // 1024 × 1024 × 1024 u32 voxels = 4 GiB, plus a 16-byte header.
    let dims = [1024usize, 1024, 1024];
    let header_bytes = 16u64;
    let len = header_bytes + 4 * (dims[0] * dims[1] * dims[2]) as u64;
    File::create(&path).unwrap().set_len(len).unwrap();
    let layout = RawLayout {
        dims,
        voxel_type: VoxelType::U32,
        endian: Endian::native(),
        header_bytes,
        spacing: [0.5, 0.5, 1.0],
        origin: [0.0; 3],
    };

    let rss_before = vm_rss_kb();
    let start = Instant::now();
    let volume = read_raw(&path, &layout).unwrap();
    let elapsed = start.elapsed();
    let rss_after = vm_rss_kb();

    assert!(volume.data.is_shared(), "voxels must be viewed in the map");
    assert_eq!(volume.data.len(), dims[0] * dims[1] * dims[2]);
    assert!(
        elapsed.as_secs_f64() < 1.0,
        "opening took {elapsed:?}: the file was read"
    );
    if let (Some(before), Some(after)) = (rss_before, rss_after) {
        let growth_mb = after.saturating_sub(before) as f64 / 1024.0;
        assert!(
            growth_mb < 16.0,
            "resident memory grew by {growth_mb:.1} MB"
        );
    }
    // Reading a few voxels touches a few pages only (sparse file reads as zeros).
    assert_eq!(volume.value_f64(1023, 1023, 1023), 0.0);
    assert_eq!(volume.value_f64(5, 700, 300), 0.0);
    if let (Some(before), Some(after)) = (rss_before, vm_rss_kb()) {
        assert!(after.saturating_sub(before) < 16 * 1024);
    }
    let VoxelData::U32(buf) = &volume.data else {
        panic!("u32 expected")
    };
    assert_eq!(buf.as_slice().len(), 1 << 30);

    // The same through `open` with the layout given as options (the CLI path).
    let options = OpenOptions {
        raw: Some(layout),
        ..OpenOptions::default()
    };
    let Dataset::Volume(v) = formats::open(&path, &options).unwrap() else {
        panic!("volume expected")
    };
    assert!(v.data.is_shared());
}
