//! The library's floors, read from the source: each top-level module's non-test code names only
//! modules on lower floors or its own, and no modules import each other in a circle. A new
//! upward arrow or circle fails here, naming the file and the module it reaches for.
//! `docs/architecture.md` draws the same floors.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The library's top-level modules, lowest floor first. The binary (`main.rs`, `cli/`) stands
/// above them all.
const FLOORS: &[&[&str]] = &[
    &["io", "numeric", "mujoco"],
    &["device", "envs"],
    &["agents", "args"],
    &["policy", "runtime"],
    &["rollout"],
    &["controller", "record", "render"],
    &["train"],
    &["evaluation"],
    &["report", "sweep"],
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

/// The file's code up to its first `#[cfg(test)]` (tests may use anything), without comments.
fn non_test_code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let code = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    code.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n")
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

/// The top-level module a file under `src/` belongs to (`agents` for `src/agents/sac/mod.rs`).
fn top_module(src: &Path, file: &Path) -> String {
    let first = file.strip_prefix(src).unwrap().components().next().unwrap();
    first.as_os_str().to_string_lossy().trim_end_matches(".rs").to_string()
}

/// Each library module's imports of other top-level modules, with the files that make them.
fn imports() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut out: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for file in files {
        let from = top_module(&src, &file);
        if ["main", "lib", "cli"].contains(&from.as_str()) {
            continue;
        }
        let entry = out.entry(from.clone()).or_default();
        for to in crate_modules(&non_test_code(&file)) {
            if to != from {
                let shown = file.strip_prefix(&src).unwrap().display().to_string();
                entry.entry(to).or_default().insert(shown);
            }
        }
    }
    out
}

fn floor(module: &str) -> Option<usize> {
    FLOORS.iter().position(|f| f.contains(&module))
}

#[test]
fn every_library_module_has_a_floor() {
    for module in imports().keys() {
        assert!(floor(module).is_some(), "src/{module} is on no floor: add it to FLOORS and docs/architecture.md");
    }
}

#[test]
fn no_module_imports_one_above_it() {
    let mut arrows = Vec::new();
    for (from, tos) in imports() {
        let Some(own) = floor(&from) else { continue };
        for (to, files) in tos {
            if floor(&to).is_some_and(|f| f > own) {
                arrows.extend(files.iter().map(|file| format!("src/{file} uses crate::{to}")));
            }
        }
    }
    assert!(arrows.is_empty(), "upward imports:\n{}", arrows.join("\n"));
}

#[test]
fn no_modules_import_each_other_in_a_circle() {
    let graph: BTreeMap<String, BTreeSet<String>> =
        imports().into_iter().map(|(from, tos)| (from, tos.into_keys().collect())).collect();
    // A circle exists iff some module reaches itself.
    for start in graph.keys() {
        let mut seen = BTreeSet::new();
        let mut stack: Vec<&String> = graph[start].iter().collect();
        while let Some(m) = stack.pop() {
            assert!(m != start, "src/{start} reaches itself through its imports ({seen:?})");
            if seen.insert(m.clone()) {
                stack.extend(graph.get(m).into_iter().flatten());
            }
        }
    }
}

#[test]
fn the_reader_finds_imports_in_paths_and_groups_and_skips_comments() {
    let code =
        "use crate::envs::Env;\nuse crate::{report::x, evaluation};\n// see crate::train\nlet a = crate::io::write();";
    assert_eq!(
        crate_modules(&code.lines().filter(|l| !l.starts_with("//")).collect::<Vec<_>>().join("\n")),
        ["envs", "report", "evaluation", "io"]
    );
}
