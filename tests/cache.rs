//! The evaluation cache's code version: `EVAL_CODE` (and `CLIP_CODE`) are the digest of the
//! source files the episodes (and clips) depend on, recomputed here independently of `build.rs`,
//! so an edit to any of them is another version, hence another key, hence a miss; edits to the
//! report's tables, the CLI or the docs are not. The other inputs of a key (env options, policy
//! bytes, protocol, push) are checked by `evaluation::cache`'s unit tests and `tests/report.rs`.
use std::path::{Path, PathBuf};

use locobench::envs::EnvConfig;
use locobench::evaluation::cache::{Key, CLIP_CODE, EVAL_CODE};
use locobench::evaluation::{EvalCache, Protocol};
use sha2::{Digest, Sha256};

fn files_under(root: &Path, skip: &[&str], out: &mut Vec<PathBuf>) {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(root).unwrap().flatten().map(|e| e.path()).collect();
    paths.sort();
    for path in paths {
        let relative = path.strip_prefix(env!("CARGO_MANIFEST_DIR")).unwrap().to_path_buf();
        if skip.iter().any(|s| relative == Path::new(s)) {
            continue;
        }
        if path.is_dir() {
            files_under(&path, skip, out);
        } else {
            out.push(relative);
        }
    }
}

/// The files each version covers, relative to the repository, in `build.rs`'s order.
fn eval_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    files_under(
        &root.join("src"),
        &["src/report", "src/cli", "src/sweep", "src/record", "src/render", "src/main.rs", "src/args.rs"],
        &mut files,
    );
    files_under(&root.join("models"), &["models/policies"], &mut files);
    files.extend(["build.rs", "Cargo.toml", "Cargo.lock"].map(PathBuf::from));
    files
}

fn clip_files() -> Vec<PathBuf> {
    let mut files = eval_files();
    files_under(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src/render"), &[], &mut files);
    files.extend(["src/report/videos.rs", "src/report/robustness_clips.rs"].map(PathBuf::from));
    files
}

/// The digest of `files`, with `changed` (a file and its new bytes) in place of its own bytes.
fn digest(files: &[PathBuf], changed: Option<(&Path, &[u8])>) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut hash = Sha256::new();
    for f in files {
        hash.update(f.to_string_lossy().as_bytes());
        hash.update([0]);
        match changed {
            Some((path, bytes)) if path == f => hash.update(bytes),
            _ => hash.update(std::fs::read(root.join(f)).unwrap()),
        }
        hash.update([0]);
    }
    hash.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

#[test]
fn the_code_versions_are_the_digests_of_the_files_the_results_depend_on() {
    let files = eval_files();
    for needed in ["src/envs/hopper.rs", "src/evaluation/protocol.rs", "src/agents/sac/mod.rs", "models/minitaur.xml"] {
        assert!(files.contains(&PathBuf::from(needed)), "{needed} decides episodes");
    }
    for not_needed in ["src/report/sections.rs", "src/cli/report.rs", "src/cli/docgen/mod.rs", "models/policies"] {
        assert!(!files.iter().any(|f| f.starts_with(not_needed)), "{not_needed} decides no episode");
    }
    assert_eq!(digest(&files, None), EVAL_CODE, "build.rs digests these files (rebuild if a file just changed)");
    assert_eq!(digest(&clip_files(), None), CLIP_CODE);
    // One byte more in an env's source is another version.
    let hopper = PathBuf::from("src/envs/hopper.rs");
    let mut edited = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join(&hopper)).unwrap();
    edited.push(b'\n');
    assert_ne!(digest(&files, Some((&hopper, &edited))), EVAL_CODE);
}

#[test]
fn a_key_names_the_code_version_and_another_version_misses() {
    let env = EnvConfig::new("hopper");
    let protocol = Protocol { episodes: 1, seed: 0 };
    let key = Key::episodes(&env, &protocol, "random 0", None, None).unwrap();
    assert!(key.text().lines().any(|l| l == format!("code = {EVAL_CODE}")), "{}", key.text());
    // An entry written by another build (the same key text but its code version) is another
    // file: this build does not find it.
    let tmp = tempfile::tempdir().unwrap();
    let cache = EvalCache::open(tmp.path()).unwrap();
    let other = key.text().replace(EVAL_CODE, &"0".repeat(EVAL_CODE.len()));
    let other_name = format!("{}.txt", locobench::io::sha256_hex(other.as_bytes()));
    std::fs::write(tmp.path().join(&other_name), format!("{other}\n")).unwrap();
    assert_ne!(other_name, format!("{}.txt", key.digest()));
    assert!(cache.lookup(&key).is_none(), "another code version's entry is not this key's");
    assert_eq!(cache.counts(), (0, 0, 0));
}
