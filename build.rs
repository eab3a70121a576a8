//! Generates Rust bindings for Debian's MuJoCo 2.2.2 (`libmujoco-dev`) with bindgen and builds
//! the small C shim that turns MuJoCo's fatal errors into return codes.
use std::path::{Path, PathBuf};

const INSTALL_HINT: &str =
    "install it with `sudo apt-get install libmujoco-dev libclang-dev` (or run scripts/setup.sh)";

fn fail(msg: &str) -> ! {
    // Cargo prints a build script's stderr when it fails: keep it to one actionable line.
    eprintln!("error: {msg}");
    std::process::exit(1);
}

/// The commit the binary is built from, for run directories' config.toml and provenance.csv
/// (`LOCOBENCH_GIT_COMMIT`; absent outside a git checkout). Rebuilt when HEAD moves or the
/// source changes.
fn record_git_commit() {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let Some(git_dir) = git(&["rev-parse", "--git-dir"]).map(PathBuf::from) else { return };
    let mut watched = vec![git_dir.join("HEAD"), git_dir.join("packed-refs")];
    watched.extend(git(&["symbolic-ref", "-q", "HEAD"]).map(|r| git_dir.join(r)));
    for path in watched.iter().filter(|p| p.exists()) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
    // What goes into the binary: an edit there since the commit marks it `-dirty`, so results
    // made with uncommitted code say so. Cargo reruns this script when any of them changes.
    let built_from = ["src", "build.rs", "Cargo.toml", "Cargo.lock", "models"];
    for path in built_from {
        println!("cargo:rerun-if-changed={path}");
    }
    if let Some(commit) = git(&["rev-parse", "HEAD"]) {
        // Modified, staged or new (untracked) files alike.
        let mut status = vec!["status", "--porcelain", "--"];
        status.extend(built_from);
        let dirty = if git(&status).is_some_and(|changes| !changes.is_empty()) { "-dirty" } else { "" };
        println!("cargo:rustc-env=LOCOBENCH_GIT_COMMIT={commit}{dirty}");
    }
}

/// Every file under `root` (recursively, sorted), skipping the folders named in `skip`.
fn files_under(root: &Path, skip: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(root) else { return };
    let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    paths.sort();
    for path in paths {
        if skip.iter().any(|s| path == Path::new(s)) {
            continue;
        }
        if path.is_dir() {
            files_under(&path, skip, out);
        } else {
            out.push(path);
        }
    }
}

/// SHA-256 over the paths and bytes of `files`, as hex.
fn digest_of(files: &[PathBuf]) -> String {
    use sha2::{Digest, Sha256};
    let mut hash = Sha256::new();
    for f in files {
        hash.update(f.to_string_lossy().as_bytes());
        hash.update([0]);
        hash.update(std::fs::read(f).unwrap_or_else(|e| fail(&format!("reading {}: {e}", f.display()))));
        hash.update([0]);
    }
    hash.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Versions of the code that decides an evaluation's numbers and a clip's pixels, for the
/// report's evaluation cache (`evaluation::cache`): a digest of the source files, so any edit
/// that could change an episode changes the version and no cached number outlives it.
/// `LOCOBENCH_EVAL_CODE`: everything the episodes depend on (physics, envs, models, agents,
/// controller, protocol, the dependency versions), not the report's tables, the CLI, sweeps or
/// docs. `LOCOBENCH_CLIP_CODE`: that, the renderer and the report's clip code.
fn record_code_versions() {
    for path in ["src", "models", "Cargo.toml", "Cargo.lock"] {
        println!("cargo:rerun-if-changed={path}");
    }
    let mut eval = Vec::new();
    files_under(
        Path::new("src"),
        &["src/report", "src/cli", "src/sweep", "src/record", "src/render", "src/main.rs", "src/args.rs"],
        &mut eval,
    );
    files_under(Path::new("models"), &["models/policies"], &mut eval);
    eval.extend(["build.rs", "Cargo.toml", "Cargo.lock"].map(PathBuf::from));
    let mut clip = eval.clone();
    files_under(Path::new("src/render"), &[], &mut clip);
    clip.extend(["src/report/videos.rs", "src/report/robustness_clips.rs"].map(PathBuf::from));
    println!("cargo:rustc-env=LOCOBENCH_EVAL_CODE={}", digest_of(&eval));
    println!("cargo:rustc-env=LOCOBENCH_CLIP_CODE={}", digest_of(&clip));
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    record_code_versions();
    println!("cargo:rerun-if-changed=src/mujoco/shim.c");
    println!("cargo:rerun-if-env-changed=MUJOCO_INCLUDE_DIR");
    println!("cargo:rerun-if-env-changed=MUJOCO_LIB_DIR");
    record_git_commit();

    let include_dir = PathBuf::from(std::env::var("MUJOCO_INCLUDE_DIR").unwrap_or_else(|_| "/usr/include".into()));
    let header = include_dir.join("mujoco/mujoco.h");
    if !header.exists() {
        fail(&format!("MuJoCo header {} not found: {INSTALL_HINT}", header.display()));
    }
    let lib_dir = std::env::var("MUJOCO_LIB_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from("/usr/lib/x86_64-linux-gnu"));
    if !has_mujoco_library(&lib_dir) {
        fail(&format!("MuJoCo library libmujoco.so not found in {}: {INSTALL_HINT}", lib_dir.display()));
    }
    println!("cargo:rustc-link-search=native={}", lib_dir.display());
    println!("cargo:rustc-link-lib=dylib=mujoco");

    let bindings = bindgen::Builder::default()
        .header(header.to_string_lossy())
        .clang_arg(format!("-I{}", include_dir.display()))
        .allowlist_function("mj_.*")
        .allowlist_function("mju_.*")
        // Rendering: the abstract scene (mjv_) and its OpenGL renderer (mjr_), src/render/.
        .allowlist_function("mj[rv]_.*")
        .allowlist_type("mj.*")
        .allowlist_var("mj.*")
        .allowlist_var("mju_user_.*")
        .derive_default(true)
        .layout_tests(false)
        .generate()
        .unwrap_or_else(|e| {
            fail(&format!("bindgen could not read {} ({e}); libclang missing? {INSTALL_HINT}", header.display()))
        });
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    bindings.write_to_file(out.join("mujoco_bindings.rs")).expect("write bindings");

    cc::Build::new()
        .file("src/mujoco/shim.c")
        .include(&include_dir)
        .flag_if_supported("-std=c11")
        .warnings(true)
        .compile("locobench_mujoco_shim");
}

fn has_mujoco_library(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .map(|entries| entries.flatten().any(|e| e.file_name().to_string_lossy().starts_with("libmujoco.so")))
        .unwrap_or(false)
}
