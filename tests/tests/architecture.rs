//! The dependency rule of `docs/architecture.md`, checked against `cargo metadata`:
//! app → formats → volume-core, data-samples → volume-core/formats, never back; no GUI, CLI or
//! `anyhow` below the app.

use std::collections::{BTreeSet, HashMap};
use std::process::Command;

use serde_json::Value;

/// Normal (non-dev, non-build) dependency edges by package name, from `cargo metadata`.
fn dependency_graph() -> HashMap<String, Vec<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = concat!(env!("CARGO_MANIFEST_DIR"), "/../Cargo.toml");
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--manifest-path",
            manifest,
        ])
        .output()
        .expect("cargo metadata runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: Value = serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON");
    let names: HashMap<&str, &str> = meta["packages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p["id"].as_str().unwrap(), p["name"].as_str().unwrap()))
        .collect();
    let mut graph = HashMap::new();
    for node in meta["resolve"]["nodes"].as_array().unwrap() {
        let from = names[node["id"].as_str().unwrap()].to_string();
        let deps = node["deps"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| {
                d["dep_kinds"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|k| k["kind"].is_null())
            })
            .map(|d| names[d["pkg"].as_str().unwrap()].to_string())
            .collect();
        graph.insert(from, deps);
    }
    graph
}

fn transitive(graph: &HashMap<String, Vec<String>>, root: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut stack = vec![root.to_string()];
    while let Some(p) = stack.pop() {
        for d in graph.get(&p).into_iter().flatten() {
            if seen.insert(d.clone()) {
                stack.push(d.clone());
            }
        }
    }
    seen
}

const GUI_AND_APP_CRATES: [&str; 6] = ["egui", "eframe", "clap", "anyhow", "rfd", "egui_kittest"];

fn assert_free_of(root: &str, extra: &[&str]) {
    let deps = transitive(&dependency_graph(), root);
    for forbidden in GUI_AND_APP_CRATES.iter().chain(extra) {
        assert!(
            !deps.contains(*forbidden),
            "{root} must not depend on {forbidden}"
        );
    }
}

#[test]
fn volume_core_depends_on_no_format_gui_or_cli_crate() {
    assert_free_of("volume-core", &["formats", "data-samples", "isoscope"]);
}

#[test]
fn formats_depends_on_no_gui_or_cli_crate_and_not_on_the_app() {
    assert_free_of("formats", &["data-samples", "isoscope"]);
}

#[test]
fn data_samples_stays_below_the_app() {
    assert_free_of("data-samples", &["isoscope"]);
}

#[test]
fn the_check_sees_the_app_depending_on_everything() {
    // Guards the check itself: with an empty graph every rule above would pass vacuously.
    let deps = transitive(&dependency_graph(), "isoscope");
    for needed in [
        "volume-core",
        "formats",
        "data-samples",
        "clap",
        "anyhow",
        "glam",
    ] {
        assert!(deps.contains(needed), "app should depend on {needed}");
    }
}
