//! Helpers shared by the integration tests that run the `locobench` binary.
#![allow(dead_code)] // each test crate uses its own subset

use std::process::Command;

/// Runs `locobench` with `args`: (success, stdout, stderr).
pub fn locobench(args: &[&str]) -> (bool, String, String) {
    locobench_with_path(args, None)
}

/// As [`locobench`], with `PATH` replaced when `path_var` is given.
pub fn locobench_with_path(args: &[&str], path_var: Option<&str>) -> (bool, String, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_locobench"));
    cmd.args(args);
    if let Some(p) = path_var {
        cmd.env("PATH", p);
    }
    let out = cmd.output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}
