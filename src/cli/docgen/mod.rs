//! The numbers in README.md and docs/ come from committed result files: each generated section
//! sits between two markers and is rewritten by `locobench docs`; `locobench docs --check` (and
//! the tests below) fail when a section differs from what the files give now.
//!
//! ```text
//! <!-- generated: NAME (locobench docs) -->
//! ...
//! <!-- end generated: NAME -->
//! ```
mod benchmarks;
mod command;
mod csv_rows;
mod envs;
mod gpu;
mod results;
mod robustness;
mod runs;

use std::path::Path;

use anyhow::{bail, Context, Result};

use locobench::io::write_bytes_atomic;

/// One generated section: the file it lives in, its marker name and its text.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// The file, relative to the repository root.
    pub file: &'static str,
    /// The marker name.
    pub name: &'static str,
    /// The generated text between the markers.
    pub text: String,
}

/// Where every generated section's data comes from, relative to the repository root.
pub(crate) const REPORT_DIR: &str = "benches/results/report";
pub(crate) const BENCH_RESULTS_DIR: &str = "benches/results";

/// Every generated section, computed from the files under `root`.
pub fn sections(root: &Path) -> Result<Vec<Section>> {
    let report = root.join(REPORT_DIR);
    Ok(vec![
        Section { file: "README.md", name: "results", text: results::glance(&report)? },
        Section { file: "docs/training.md", name: "curves", text: results::curves(&report)? },
        Section {
            file: "docs/training.md",
            name: "minitaur-probes",
            text: command::probes(root, "benches/results/minitaur/probes-100k/probes.csv")?,
        },
        Section { file: "docs/training.md", name: "minitaur-selection", text: results::minitaur_selection(&report)? },
        Section { file: "docs/controller.md", name: "controller-speeds", text: results::controller(&report)? },
        Section { file: "docs/benchmarks.md", name: "speed", text: benchmarks::speed(&root.join(BENCH_RESULTS_DIR))? },
        Section {
            file: "docs/benchmarks.md",
            name: "memory",
            text: benchmarks::memory(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "docs/benchmarks.md",
            name: "time-to-walk",
            text: benchmarks::time_to_walk(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "docs/benchmarks.md",
            name: "time-to-track",
            text: benchmarks::time_to_track(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "docs/benchmarks.md",
            name: "vector-env",
            text: benchmarks::vector_env(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "docs/benchmarks.md",
            name: "render-speed",
            text: benchmarks::render_speed(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "docs/evaluation.md",
            name: "ppo-vs-sb3",
            text: benchmarks::ppo_vs_sb3(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "docs/evaluation.md",
            name: "report-timing",
            text: benchmarks::report_timing(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section { file: "docs/gpu.md", name: "gpu-speed", text: gpu::speed(&root.join(BENCH_RESULTS_DIR))? },
        Section { file: "docs/gpu.md", name: "gpu-check", text: gpu::check(&root.join(BENCH_RESULTS_DIR))? },
        Section {
            file: "docs/gpu.md",
            name: "gpu-crossq",
            text: gpu::crossq_curve(
                &root.join(BENCH_RESULTS_DIR),
                Path::new("benches/results/half-cheetah/crossq-256-seed0"),
                root,
            )?,
        },
        Section { file: "docs/environments.md", name: "envs", text: envs::table()? },
        Section { file: "docs/environments.md", name: "minitaur-tracking", text: command::tracking(root, "minitaur")? },
        Section {
            file: "docs/robustness.md",
            name: "robustness",
            text: robustness::summary(&root.join(BENCH_RESULTS_DIR), "minitaur")?,
        },
        Section {
            file: "docs/robustness.md",
            name: "robustness-ant",
            text: robustness::summary(&root.join(BENCH_RESULTS_DIR), "ant")?,
        },
        Section {
            file: "docs/python.md",
            name: "python-speed",
            text: benchmarks::python_speed(&root.join(BENCH_RESULTS_DIR))?,
        },
        Section {
            file: "benches/results/README.md",
            name: "runs",
            text: runs::list(root, &["benches/results", "models/policies"])?,
        },
    ])
}

fn begin_marker(name: &str) -> String {
    format!("<!-- generated: {name} (locobench docs) -->")
}

fn end_marker(name: &str) -> String {
    format!("<!-- end generated: {name} -->")
}

/// `doc` with the text between `name`'s markers replaced by `text`.
pub(crate) fn splice(doc: &str, name: &str, text: &str) -> Result<String> {
    let (begin, end) = (begin_marker(name), end_marker(name));
    let Some(start) = doc.find(&begin) else { bail!("no '{begin}' marker") };
    let body = start + begin.len();
    let Some(stop) = doc[body..].find(&end).map(|i| body + i) else { bail!("no '{end}' after '{begin}'") };
    if doc[stop + end.len()..].contains(&begin) {
        bail!("'{begin}' appears twice");
    }
    Ok(format!("{}\n{}\n{}", &doc[..body], text.trim_end(), &doc[stop..]))
}

/// Each file with its generated sections as they would be written now, and the names of the
/// sections whose text differs from the file's.
fn render(root: &Path) -> Result<Vec<(String, String, Vec<&'static str>)>> {
    let mut files: Vec<(String, String, Vec<&'static str>)> = Vec::new();
    for s in sections(root)? {
        let i = match files.iter().position(|(f, _, _)| f == s.file) {
            Some(i) => i,
            None => {
                let path = root.join(s.file);
                let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
                files.push((s.file.to_string(), text, Vec::new()));
                files.len() - 1
            }
        };
        let (file, text, changed) = &mut files[i];
        let new = splice(text, s.name, &s.text).with_context(|| format!("section '{}' of {file}", s.name))?;
        if new != *text {
            changed.push(s.name);
            *text = new;
        }
    }
    Ok(files)
}

/// `file: section` for every generated section that is not what the files give now.
pub fn stale(root: &Path) -> Result<Vec<String>> {
    Ok(render(root)?
        .into_iter()
        .flat_map(|(file, _, changed)| changed.into_iter().map(move |s| format!("{file}: {s}")))
        .collect())
}

/// Rewrites every stale section in place; returns what changed (`file: section`).
pub fn write(root: &Path) -> Result<Vec<String>> {
    let mut changed = Vec::new();
    for (file, text, sections) in render(root)? {
        if !sections.is_empty() {
            write_bytes_atomic(&root.join(&file), text.as_bytes())?;
            changed.extend(sections.into_iter().map(|s| format!("{file}: {s}")));
        }
    }
    Ok(changed)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    #[test]
    fn splice_replaces_only_between_the_markers() {
        let doc = format!("intro\n{}\nold\n{}\noutro\n", begin_marker("a"), end_marker("a"));
        let new = splice(&doc, "a", "new\n").unwrap();
        assert_eq!(new, format!("intro\n{}\nnew\n{}\noutro\n", begin_marker("a"), end_marker("a")));
        assert_eq!(splice(&new, "a", "new").unwrap(), new, "splicing the same text changes nothing");
    }

    #[test]
    fn missing_or_repeated_markers_are_errors() {
        assert!(splice("no markers", "a", "x").unwrap_err().to_string().contains("generated: a"));
        let open = format!("{}\n", begin_marker("a"));
        assert!(splice(&open, "a", "x").unwrap_err().to_string().contains("end generated: a"));
        let twice = format!("{0}\n{1}\n{0}\n{1}\n", begin_marker("a"), end_marker("a"));
        assert!(splice(&twice, "a", "x").unwrap_err().to_string().contains("twice"));
    }

    #[test]
    fn generated_sections_are_up_to_date() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let stale = stale(root).unwrap();
        assert!(stale.is_empty(), "stale generated sections (run `locobench docs`): {stale:?}");
    }

    #[test]
    fn every_generated_section_quotes_data() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        for s in sections(root).unwrap() {
            let rows = s.text.lines().filter(|l| l.starts_with("| ") && !l.starts_with("|--")).count();
            assert!(rows >= 2, "{}: {} has no table rows:\n{}", s.file, s.name, s.text);
        }
    }
}
