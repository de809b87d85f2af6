//! Helpers shared by the CLI end-to-end tests: run the real `isoscope` binary.

#![allow(dead_code)] // each test binary uses its own subset

use std::process::{Command, Output};

/// Runs `isoscope ARGS` with backtraces off, so error output is what a user sees.
pub fn isoscope(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_isoscope"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .output()
        .expect("run isoscope")
}

/// Runs `isoscope ARGS`, asserts success and returns stdout.
pub fn ok(args: &[&str]) -> String {
    let out = isoscope(args);
    assert!(
        out.status.success(),
        "isoscope {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Runs `isoscope ARGS`, asserts failure and returns stderr.
pub fn fails(args: &[&str]) -> String {
    let out = isoscope(args);
    assert!(!out.status.success(), "isoscope {args:?} should fail");
    String::from_utf8(out.stderr).unwrap()
}
