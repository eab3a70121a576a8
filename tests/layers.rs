//! The import rules between the library's folders that hold today, read from the source: each
//! folder's non-test code names no module of the folders above it. A new upward arrow fails here
//! with the file and the module it reaches for.
use std::path::{Path, PathBuf};

/// Folders (or top-level files) and the modules their non-test code must not use.
const RULES: &[(&str, &[&str])] = &[
    ("mujoco", &["envs", "agents", "controller", "evaluation", "report", "render", "train", "cli", "docgen", "sweep"]),
    ("numeric", &["envs", "agents", "controller", "evaluation", "report", "render", "train", "cli", "docgen", "sweep"]),
    ("envs", &["agents", "controller", "evaluation", "report", "render", "train", "cli", "docgen", "sweep"]),
    ("render", &["evaluation", "report", "cli", "docgen", "sweep"]),
    ("evaluation", &["report", "cli", "docgen", "sweep"]),
    ("train", &["evaluation", "report", "cli", "docgen", "sweep"]),
    ("report", &["cli", "sweep"]),
];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The file's text up to its first `#[cfg(test)]` (tests may use anything).
fn non_test_code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    match text.find("#[cfg(test)]") {
        Some(i) => text[..i].to_string(),
        None => text,
    }
}

/// Every `crate::<module>` a piece of code names, `use crate::{a, b}` groups included.
fn crate_modules(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let inner = &group[..group.find('}').unwrap_or(group.len())];
            out.extend(inner.split(',').map(|p| p.trim().split("::").next().unwrap_or("").to_string()));
        } else {
            out.push(rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect());
        }
    }
    out.retain(|m| !m.is_empty());
    out
}

#[test]
fn no_folder_imports_one_above_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut arrows = Vec::new();
    for (folder, above) in RULES {
        let mut files = Vec::new();
        rust_files(&src.join(folder), &mut files);
        assert!(!files.is_empty(), "src/{folder} has no files: the rule names a folder that moved");
        for file in files {
            for module in crate_modules(&non_test_code(&file)) {
                if above.contains(&module.as_str()) {
                    arrows.push(format!("{} uses crate::{module}", file.strip_prefix(&src).unwrap().display()));
                }
            }
        }
    }
    arrows.sort();
    arrows.dedup();
    assert!(arrows.is_empty(), "upward imports:\n{}", arrows.join("\n"));
}

#[test]
fn the_reader_finds_imports_in_paths_and_groups() {
    let code = "use crate::envs::Env;\nuse crate::{report::x, evaluation};\nlet a = crate::io::write();";
    assert_eq!(crate_modules(code), ["envs", "report", "evaluation", "io"]);
}
