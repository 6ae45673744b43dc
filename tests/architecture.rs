//! The library's layers, checked from the source: each module of `src/` may use only the modules below it in
//! [`LAYERS`], so the modules form no cycle and a new upward import fails here, naming the file (an ArchUnit-style
//! test; docs/architecture.md describes the layers). Test modules are exempt: a test may build its fixtures with any
//! stage. A new top-level module must be given its place in the table.

#![allow(clippy::expect_used)]

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The library's modules from the bottom up; a module may use the modules listed before it.
const LAYERS: &[(&str, &str)] = &[
    ("error", "rendering errors once, at the edge"),
    ("image", "the depth image type"),
    ("seed", "seed hashing"),
    (
        "io",
        "file formats and safe writing: atomic files, locks, npy, PLY, PNG previews, figures",
    ),
    (
        "mesh",
        "meshes: loading, ray casting, signed distances, surface samples",
    ),
    (
        "sensor",
        "camera, membrane, sensor pose, resampling of native frames",
    ),
    ("sim", "the contact simulator and synthetic signatures"),
    ("recon", "back-projection of depth to points"),
    ("rrd", "rerun recordings of images, points and meshes"),
    (
        "objects",
        "object sets: built-in, imported and procedural objects",
    ),
    (
        "recording",
        "real sensor recordings: MCAP and frame folders, imprints, calibration",
    ),
    ("dataset", "synthetic and imported datasets"),
    ("model::kernels", "CPU kernels of the U-Net"),
    ("model", "the conditional diffusion model"),
    (
        "pose",
        "SE(2) registration, the baseline, the signature check",
    ),
    ("metrics", "scores of depth and pose, the evaluation loop"),
    ("uncertainty", "sample spread, pose modes, KDE"),
    ("pipeline", "the use cases the CLI and the workbench run"),
];

fn rank(node: &str) -> Option<usize> {
    LAYERS.iter().position(|(n, _)| *n == node)
}

/// The module path of a source file: `src/model/kernels/conv_direct.rs` → `model::kernels::conv_direct`.
fn module_path(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if let Some(last) = parts.pop() {
        let stem = last.trim_end_matches(".rs").to_string();
        if stem != "mod" && stem != "lib" {
            parts.push(stem);
        }
    }
    parts
}

/// The layer a module path belongs to.
fn node_of(path: &[String]) -> Option<String> {
    match path {
        [] => None,
        [m, k, ..] if m == "model" && k == "kernels" => Some("model::kernels".into()),
        [first, ..] => Some(first.clone()),
    }
}

/// The source without comments, string literals and `#[cfg(test)]` items.
fn code_only(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < bytes.len() {
        if text[i..].starts_with("//") {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
        } else if text[i..].starts_with("/*") {
            let mut depth = 0;
            while i < bytes.len() {
                if text[i..].starts_with("/*") {
                    depth += 1;
                    i += 2;
                } else if text[i..].starts_with("*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if text[i..].starts_with("r#\"") {
            let close = text[i + 3..]
                .find("\"#")
                .map_or(text.len(), |p| i + 3 + p + 2);
            i = close;
            out.push_str("\"\"");
        } else if bytes[i] == b'"' && !text[..i].ends_with('\'') {
            i += 1;
            while i < bytes.len() && bytes[i] != b'"' {
                i += if bytes[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if text[i..].starts_with("#[cfg(test)]") {
            // Skip the attribute, further attributes, and the item up to its balanced closing brace (or `;`).
            let mut depth = 0usize;
            let mut seen_brace = false;
            i += "#[cfg(test)]".len();
            while i < bytes.len() {
                match bytes[i] {
                    b'{' => {
                        depth += 1;
                        seen_brace = true;
                    }
                    b'}' => {
                        depth -= 1;
                        if depth == 0 && seen_brace {
                            i += 1;
                            break;
                        }
                    }
                    b';' if !seen_brace => {
                        i += 1;
                        break;
                    }
                    _ => {}
                }
                i += 1;
            }
        } else {
            let c = text[i..].chars().next().unwrap_or(' ');
            out.push(c);
            i += c.len_utf8();
        }
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Module paths (absolute, from the crate root) that `code` of module `here` refers to.
fn references(code: &str, here: &[String]) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    let chars: Vec<char> = code.chars().collect();
    let word_at = |i: usize| -> (String, usize) {
        let mut j = i;
        while j < chars.len() && is_ident(chars[j]) {
            j += 1;
        }
        (chars[i..j].iter().collect(), j)
    };
    let mut i = 0;
    while i < chars.len() {
        let boundary = i == 0 || !is_ident(chars[i - 1]) && chars[i - 1] != ':';
        if !boundary || !(chars[i] == 'c' || chars[i] == 's') {
            i += 1;
            continue;
        }
        let (word, end) = word_at(i);
        let mut base: Vec<String> = match word.as_str() {
            "crate" => Vec::new(),
            "super" => here[..here.len().saturating_sub(1)].to_vec(),
            _ => {
                i = end.max(i + 1);
                continue;
            }
        };
        let mut j = end;
        // Further `super::` and path segments.
        loop {
            if !(j + 1 < chars.len() && chars[j] == ':' && chars[j + 1] == ':') {
                break;
            }
            j += 2;
            if j < chars.len() && chars[j] == '{' {
                // A group: every member's first segment.
                // Members at the group's own level (a nested group belongs to the member before it).
                let mut depth = 0;
                let mut members = vec![String::new()];
                let mut close = chars.len();
                for (k, &c) in chars.iter().enumerate().skip(j + 1) {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => {
                            close = k;
                            break;
                        }
                        '}' => depth -= 1,
                        ',' if depth == 0 => members.push(String::new()),
                        _ => {}
                    }
                    if let Some(m) = members.last_mut() {
                        m.push(c);
                    }
                }
                for member in members {
                    let first: String = member
                        .trim_start_matches(',')
                        .trim()
                        .chars()
                        .take_while(|&c| is_ident(c))
                        .collect();
                    if !first.is_empty() && first != "self" {
                        let mut p = base.clone();
                        p.push(first);
                        found.push(p);
                    }
                }
                base.clear();
                j = close;
                break;
            }
            let (seg, e) = word_at(j);
            if seg.is_empty() {
                break;
            }
            if seg == "super" {
                base.pop();
            } else {
                base.push(seg);
            }
            j = e;
            if base.len() >= 2 {
                break;
            }
        }
        if !base.is_empty() {
            found.push(base);
        }
        i = j.max(i + 1);
    }
    found
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let path = entry.expect("entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn every_module_uses_only_the_layers_below_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut violations = BTreeSet::new();
    let mut unplaced = BTreeSet::new();
    let mut checked = 0;
    for file in files {
        let rel = file.strip_prefix(&src).expect("under src").to_path_buf();
        if rel.starts_with("bin") {
            continue;
        }
        // Whole test files (`foo_tests.rs`, included under `#[cfg(test)]`) are tests.
        let name = rel
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if name.ends_with("_tests.rs") || name == "tests.rs" {
            continue;
        }
        let here = module_path(&rel);
        let Some(node) = node_of(&here) else { continue };
        let Some(own) = rank(&node) else {
            unplaced.insert(format!("{node} ({})", rel.display()));
            continue;
        };
        let text = std::fs::read_to_string(&file).expect("read source");
        for target in references(&code_only(&text), &here) {
            let Some(to) = node_of(&target) else { continue };
            if to == node {
                continue;
            }
            match rank(&to) {
                Some(r) if r < own => {}
                // A name that is not a module of ours (`crate::Foo` re-exports, macros) is not a layer.
                None if !src.join(&to).is_dir() && !src.join(format!("{to}.rs")).is_file() => {}
                _ => {
                    violations.insert(format!("{} ({node}) uses {to}", rel.display()));
                }
            }
        }
        checked += 1;
    }
    assert!(checked > 100, "only {checked} files checked");
    assert!(
        unplaced.is_empty(),
        "modules without a place in LAYERS (add them where they belong): {unplaced:#?}"
    );
    assert!(
        violations.is_empty(),
        "imports against the layers (a module may use only those below it in LAYERS; move the shared piece \
         down instead): {violations:#?}"
    );
}

/// The checker itself finds what it must: an upward `use`, a grouped one, a `super::super` path into another layer,
/// and nothing in comments, strings or test modules.
#[test]
fn the_checker_sees_uses_and_skips_comments_strings_and_tests() {
    let here: Vec<String> = ["model", "kernels", "conv"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let code = code_only(
        "use crate::pose::Se2;\nuse crate::{dataset, io::{npy, ply}};\n// crate::uncertainty in a comment\n\
         let s = \"crate::metrics\";\nuse super::super::unet;\n#[cfg(test)]\nmod tests {\n use crate::pipeline;\n}\n",
    );
    let nodes: BTreeSet<String> = references(&code, &here)
        .iter()
        .filter_map(|p| node_of(p))
        .collect();
    let want: BTreeSet<String> = ["pose", "dataset", "io", "model"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(nodes, want);
    let own: Vec<String> = ["model", "kernels", "attention", "rows"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let nodes: Vec<Option<String>> = references("use super::super::simd::exp_f32;", &own)
        .iter()
        .map(|p| node_of(p))
        .collect();
    assert_eq!(nodes, vec![Some("model::kernels".to_string())]);
}
