//! The generated sections of README.md and docs/ match the committed result files.
use std::path::Path;

#[test]
fn generated_sections_are_up_to_date() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let stale = locobench::docgen::stale(root).unwrap();
    assert!(stale.is_empty(), "stale generated sections (run `locobench docs`): {stale:?}");
}

#[test]
fn every_generated_section_quotes_data() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for s in locobench::docgen::sections(root).unwrap() {
        let rows = s.text.lines().filter(|l| l.starts_with("| ") && !l.starts_with("|--")).count();
        assert!(rows >= 2, "{}: {} has no table rows:\n{}", s.file, s.name, s.text);
    }
}
