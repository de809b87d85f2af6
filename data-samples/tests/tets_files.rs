//! Generated tet meshes survive the writers and readers of `formats::mesh`, and the moving
//! Gaussian written as numbered files reads back as a time series with shared topology in
//! which only the scalars change.

use std::path::PathBuf;

use data_samples::tets::{MOVING_STEPS, TetShape, moving_gaussian_steps, tet_mesh};
use formats::mesh::{self, LegacyEncoding, MeshSeries};
use volume_core::tet::{PointField, TetMesh};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("isoscope-tets-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn generated_meshes_round_trip_through_vtu_and_legacy() {
    let dir = scratch("roundtrip");
    for shape in TetShape::ALL {
        let m = tet_mesh(shape, 14).unwrap();
        let vtu = dir.join(format!("{shape}.vtu"));
        mesh::write_vtu(&vtu, &m, formats::output::Replace::Refuse).unwrap();
        assert_eq!(mesh::read_mesh(&vtu).unwrap().mesh, m, "{shape} vtu");
        let vtk = dir.join(format!("{shape}.vtk"));
        mesh::write_vtk_legacy(
            &vtk,
            &m,
            LegacyEncoding::Binary,
            formats::output::Replace::Refuse,
        )
        .unwrap();
        assert_eq!(mesh::read_mesh(&vtk).unwrap().mesh, m, "{shape} vtk");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn moving_gaussian_series_reads_back_with_shared_topology() {
    let dir = scratch("series");
    let m = tet_mesh(TetShape::Shell, 12).unwrap();
    let steps = moving_gaussian_steps(&m, MOVING_STEPS);
    for (s, values) in steps.iter().enumerate() {
        let step = TetMesh::new(
            m.points.clone(),
            m.tets.clone(),
            vec![PointField::new("moving_gaussian", values.clone())],
        )
        .unwrap();
        mesh::write_vtu(
            &dir.join(format!("moving_{s:02}.vtu")),
            &step,
            formats::output::Replace::Refuse,
        )
        .unwrap();
    }
    let series = MeshSeries::numbered(&dir.join("moving_00.vtu")).unwrap();
    assert_eq!(series.len(), MOVING_STEPS);
    let first = series.load_step(0).unwrap().mesh;
    for (s, values) in steps.iter().enumerate() {
        let d = series.load_step_data(s, &first).unwrap();
        assert!(d.positions.is_none(), "step {s}: only scalars change");
        assert_eq!(&d.fields[0].values, values, "step {s}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
