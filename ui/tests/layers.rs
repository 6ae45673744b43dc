//! The workbench's layers, checked from the source (as `tests/architecture.rs` checks the core's): the app
//! (`src/app/`: the `WorkbenchApp` struct, its frame loop, the command dispatcher and the code that starts jobs and
//! takes in their messages) is the only place with `impl WorkbenchApp`; the panels (`src/panels/`) read the app and
//! push commands; every other module — state, commands, jobs, views, the 3D view — is below the app and never
//! names it, so a job can be read, tested and reused without the window around it.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The code of a file without `//` comments (doc comments may name the app).
fn code(path: &Path) -> String {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn only_the_app_implements_the_app_and_only_panels_and_the_app_name_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    assert!(
        files.len() > 20,
        "found only {} files under {}",
        files.len(),
        src.display()
    );
    let mut problems = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).unwrap();
        let top = rel.iter().next().unwrap().to_string_lossy().into_owned();
        let text = code(file);
        let in_app = top == "app";
        let may_name_app = in_app || top == "panels" || top == "main.rs" || top == "lib.rs";
        let implements = text
            .lines()
            .any(|l| l.trim_start().starts_with("impl") && l.contains("WorkbenchApp"));
        if implements && !in_app {
            problems.push(format!(
                "{}: implements WorkbenchApp outside src/app/",
                rel.display()
            ));
        }
        if !may_name_app && (text.contains("crate::app") || text.contains("WorkbenchApp")) {
            problems.push(format!(
                "{}: names the app (only src/app/ and src/panels/ may)",
                rel.display()
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}
