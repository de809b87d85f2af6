//! Fuzzes the mesh parsers (legacy VTK, VTK XML, Gmsh) and the cell validation/splitting:
//! any input must give `Ok` or a `MeshError`, never a panic, hang or huge allocation.
//! The first byte picks the parser; seeds: `formats/tests/data/mesh/*.{vtk,vtu,msh}` with a
//! selector byte prepended (0 = vtk, 1 = vtu, 2 = msh).
#![no_main]

use std::path::Path;

use formats::mesh::{gmsh, vtk_legacy, vtu};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, bytes)) = data.split_first() else {
        return;
    };
    let path = Path::new("fuzz.mesh");
    let raw = match selector % 3 {
        0 => vtk_legacy::parse(path, bytes),
        1 => vtu::parse(path, bytes),
        _ => gmsh::parse(path, bytes),
    };
    if let Ok(raw) = raw {
        let _ = raw.into_tet_mesh(path);
    }
});
