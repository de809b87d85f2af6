//! The hostile corpus (`data_samples::hostile`) in the real viewer: `ViewerApp` with the real
//! `CoreBackend`, driven headless by egui_kittest, opens every case one after another in one
//! harness.
//!
//! - A bad case gives an error notification (a case whose damage is in a later time step
//!   gives it when that step is shown), and the viewer keeps running: frames still step, the
//!   previous data stays or the view is empty, no job is left busy.
//! - A valid case loads (the loaded data is that file).
//! - After the whole corpus a valid file still opens and renders a frame.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use data_samples::hostile::{Case, Expect, write_corpus};
use egui_kittest::Harness;
use isoscope::ui::app::ViewerApp;
use isoscope::ui::backend::CoreBackend;
use isoscope::ui::commands::Command;

/// Longest one case may take to give its answer (the CLI test bounds each run at 8 s).
const CASE_TIMEOUT: Duration = Duration::from_secs(20);

/// Steps the app until `done` holds; `Err` after [`CASE_TIMEOUT`].
fn step_until(
    h: &mut Harness<'_, ViewerApp>,
    done: impl Fn(&ViewerApp) -> bool,
) -> Result<(), String> {
    let start = Instant::now();
    while !done(h.state()) {
        if start.elapsed() > CASE_TIMEOUT {
            return Err(format!(
                "no answer within {CASE_TIMEOUT:?}; busy {}, last notes {:?}",
                h.state().is_busy(),
                h.state()
                    .notifications()
                    .iter()
                    .rev()
                    .take(2)
                    .map(|n| n.text.clone())
                    .collect::<Vec<_>>()
            ));
        }
        h.step();
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(())
}

fn error_count(app: &ViewerApp) -> usize {
    app.notifications().iter().filter(|n| n.is_error).count()
}

/// True when the error notifications after the first `before` name one of the case's files.
fn new_error_names_case(app: &ViewerApp, before: usize, case: &Case) -> bool {
    app.notifications()
        .iter()
        .filter(|n| n.is_error)
        .skip(before)
        .any(|n| case.names.iter().any(|name| n.text.contains(name.as_str())))
}

/// Opens one case and checks the viewer's answer.
fn open_case(h: &mut Harness<'_, ViewerApp>, case: &Case) -> Result<(), String> {
    let errors = error_count(h.state());
    let loaded = h.state().stats.datasets_loaded;
    h.state_mut()
        .push(Command::OpenFiles(vec![case.open.clone()]));
    h.step();
    step_until(h, |a| {
        !a.is_busy() && (error_count(a) > errors || a.stats.datasets_loaded > loaded)
    })?;
    match (case.expect, case.bad_step) {
        // Valid data without a finite value (all-NaN): the CLI needs an explicit `--iso`
        // (`render_args`); the viewer has no isovalue to start from and says so.
        (Expect::Renders, _) if !case.render_args.is_empty() => {
            let loaded_it = h.state().data().and_then(|d| d.path.as_ref()) == Some(&case.open);
            if !loaded_it && !new_error_names_case_file(h.state(), errors, case) {
                return Err(format!(
                    "neither loaded nor a notification naming it: {:?}",
                    last_error(h.state())
                ));
            }
        }
        (Expect::Renders, _) => {
            if error_count(h.state()) > errors {
                return Err(format!(
                    "error for a valid file: {:?}",
                    last_error(h.state())
                ));
            }
            let shown = h.state().data().and_then(|d| d.path.clone());
            if shown.as_ref() != Some(&case.open) {
                return Err(format!("loaded {shown:?}, not the case's file"));
            }
        }
        (Expect::Error, None) => {
            if !new_error_names_case(h.state(), errors, case) {
                return Err(format!(
                    "no error notification naming {:?}; last error {:?}, loaded {}",
                    case.names,
                    last_error(h.state()),
                    h.state().stats.datasets_loaded > loaded
                ));
            }
        }
        (Expect::Error, Some(step)) => {
            // Step 0 is valid and loads (or the open itself already failed); showing the
            // damaged step must give the error.
            if error_count(h.state()) == errors {
                h.state_mut().push(Command::SetStep(step));
                h.step();
                step_until(h, |a| !a.is_busy() && error_count(a) > errors)?;
            }
            if !new_error_names_case(h.state(), errors, case) {
                return Err(format!(
                    "no error notification naming {:?} at step {step}; last error {:?}",
                    case.names,
                    last_error(h.state())
                ));
            }
        }
    }
    // The app keeps running: the next case's open steps it again, and after the last case
    // a valid file must still open and render (`corpus_shard`). No extra frames here: at
    // the test profile egui and accesskit are unoptimized, and a frame is most of a case.
    Ok(())
}

/// Like [`new_error_names_case`], by the bare file name (messages about values, not files,
/// name the file as the scene does).
fn new_error_names_case_file(app: &ViewerApp, before: usize, case: &Case) -> bool {
    let name = case
        .open
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    app.notifications()
        .iter()
        .filter(|n| n.is_error)
        .skip(before)
        .any(|n| n.text.contains(&name))
}

fn last_error(app: &ViewerApp) -> Option<String> {
    app.notifications()
        .iter()
        .rev()
        .find(|n| n.is_error)
        .map(|n| n.text.clone())
}

// Two shards, each its own viewer, so that the two run on both cores (one viewer steps on
// one thread most of the time).
#[cfg(unix)]
#[test]
fn every_corpus_file_gives_a_notification_and_the_viewer_keeps_running_even_cases() {
    corpus_shard(0);
}

#[cfg(unix)]
#[test]
fn every_corpus_file_gives_a_notification_and_the_viewer_keeps_running_odd_cases() {
    corpus_shard(1);
}

/// Opens every other case of the corpus (`shard` 0: even indices, 1: odd) in one viewer.
fn corpus_shard(shard: usize) {
    let dir = tempfile::tempdir().unwrap();
    let all = write_corpus(dir.path()).unwrap();
    let cases: Vec<&Case> = all.iter().skip(shard).step_by(2).collect();
    assert!(cases.len() > 400, "{} cases", cases.len());
    // Error notifications quote file contents and names, decoded lossily: U+FFFD and any
    // other character can appear. The viewer (egui's default policy) draws a box for a
    // character no font has; kittest panics by default, so use the viewer's policy.
    let mut h = Harness::builder()
        .with_size(egui::vec2(640.0, 480.0))
        .allow_missing_glyphs()
        .build_eframe(|cc| {
            ViewerApp::with_backend(&cc.egui_ctx, Arc::new(CoreBackend), Vec::<PathBuf>::new())
        });
    // The embedded sample first, so that the viewer has data to keep.
    step_until(&mut h, |a| a.data().is_some() && !a.is_busy()).unwrap();

    let start = Instant::now();
    let mut failures = Vec::new();
    for &case in &cases {
        if let Err(e) = open_case(&mut h, case) {
            failures.push(format!("{}: {e}", case.name));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed in the viewer:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );

    // After the whole corpus, a valid file still opens and a frame of it is shown.
    let valid = all
        .iter()
        .find(|c| c.expect == Expect::Renders && c.name == "nrrd_raw_u8")
        .expect("the corpus has nrrd_raw_u8");
    let frames = h.state().stats.renders_shown;
    open_case(&mut h, valid).unwrap();
    step_until(&mut h, |a| {
        a.stats.renders_shown > frames
            && a.shown_frame().is_some()
            && a.data().and_then(|d| d.path.as_ref()) == Some(&valid.open)
    })
    .unwrap();
    eprintln!(
        "viewer, shard {shard}: {} cases in {:.0} s",
        cases.len(),
        start.elapsed().as_secs_f64()
    );
}
