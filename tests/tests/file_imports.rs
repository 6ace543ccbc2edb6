//! No two files of a crate import each other, directly or round a longer circle: a reader
//! can take the files of a crate in an order in which each uses only what came before.
//!
//! A file's imports are the `crate::…` paths in its code (comments and the `#[cfg(test)]`
//! module left out), `use crate::{a::X, b::{Y, Z}}` groups included, each resolved to the
//! longest module path it names, or, for an item the crate root re-exports
//! (`crate::Item`), to the module the root's `pub use` takes it from.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn crates_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates")
}

/// Every `.rs` file below `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable source folder") {
        let path = entry.expect("a folder entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `a::b` for `src/a/b.rs`; `""` for `lib.rs` and `main.rs`; `a` for `src/a/mod.rs`.
fn module_of(src: &Path, file: &Path) -> String {
    let relative = file
        .strip_prefix(src)
        .expect("below src")
        .with_extension("");
    let mut parts: Vec<String> = relative
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("lib" | "main" | "mod")
    ) {
        parts.pop();
    }
    parts.join("::")
}

/// The code of a file: without comment lines and without its test module.
fn code(text: &str) -> String {
    let before_tests = text.split("#[cfg(test)]").next().unwrap_or("");
    before_tests
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The paths a `use` group `{…}` (without its braces) names, prefixed by `prefix`.
fn expand_group(prefix: &str, group: &str, out: &mut Vec<String>) {
    let (mut depth, mut start) = (0usize, 0usize);
    let mut parts = Vec::new();
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth = depth.saturating_sub(1),
            ',' if depth == 0 => {
                parts.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&group[start..]);
    for part in parts.iter().map(|p| p.trim()).filter(|p| !p.is_empty()) {
        match part.split_once("::{") {
            Some((head, rest)) => {
                let inner = rest.strip_suffix('}').unwrap_or(rest);
                expand_group(&format!("{prefix}{head}::"), inner, out);
            }
            None => {
                let name = part.split(" as ").next().unwrap_or(part).trim();
                out.push(format!("{prefix}{name}"));
            }
        }
    }
}

/// Every `crate::…` path in `code`.
fn crate_paths(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // e.g. `dhct_crate::`
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 1;
            let end = group
                .char_indices()
                .find(|&(_, c)| {
                    depth += match c {
                        '{' => 1,
                        '}' => -1,
                        _ => 0,
                    };
                    depth == 0
                })
                .map_or(group.len(), |(i, _)| i);
            expand_group("", &group[..end], &mut out);
        } else {
            let end = rest
                .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                .unwrap_or(rest.len());
            out.push(rest[..end].trim_end_matches(':').to_string());
        }
    }
    out
}

/// Items the crate root re-exports, with the module each comes from.
fn root_reexports(lib: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for statement in code(lib).split(';') {
        let Some(path) = statement.trim().strip_prefix("pub use ") else {
            continue;
        };
        let mut items = Vec::new();
        expand_group("", path, &mut items);
        for item in items {
            if let Some((module, name)) = item.rsplit_once("::") {
                out.insert(name.to_string(), module.to_string());
            }
        }
    }
    out
}

/// The module `path` (as written after `crate::`) resolves to, if it is one of `modules`.
fn resolve(
    path: &str,
    modules: &BTreeSet<String>,
    reexports: &BTreeMap<String, String>,
) -> Option<String> {
    let parts: Vec<&str> = path.split("::").filter(|p| !p.is_empty()).collect();
    for k in (1..=parts.len()).rev() {
        let candidate = parts[..k].join("::");
        if modules.contains(&candidate) {
            return Some(candidate);
        }
    }
    let mut module = reexports.get(*parts.first()?)?.clone();
    while !modules.contains(&module) {
        module = module.rsplit_once("::")?.0.to_string();
    }
    Some(module)
}

/// One circle of imports among `graph`'s files, if there is one.
fn find_circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            let mut circle = path[at..].to_vec();
            circle.push(node.to_string());
            return Some(circle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(circle) = visit(next, graph, path, done) {
                return Some(circle);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
}

/// Each file's imports of other files of its crate.
fn import_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeSet<String> = files.iter().map(|f| module_of(src, f)).collect();
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap_or_default();
    let reexports = root_reexports(&lib);
    let mut graph = BTreeMap::new();
    for file in &files {
        let module = module_of(src, file);
        let text = std::fs::read_to_string(file).expect("readable source file");
        let imports: BTreeSet<String> = crate_paths(&code(&text))
            .iter()
            .filter_map(|p| resolve(p, &modules, &reexports))
            .filter(|m| *m != module && !m.is_empty())
            .collect();
        if !module.is_empty() {
            graph.insert(module, imports);
        }
    }
    graph
}

#[test]
fn no_two_files_of_a_crate_import_each_other() {
    let mut circles = Vec::new();
    let mut crates: Vec<PathBuf> = std::fs::read_dir(crates_dir())
        .expect("crates/")
        .map(|e| e.expect("a folder entry").path().join("src"))
        .filter(|src| src.is_dir())
        .collect();
    crates.sort();
    for src in &crates {
        if let Some(circle) = find_circle(&import_graph(src)) {
            let name = src.parent().and_then(Path::file_name).unwrap_or_default();
            circles.push(format!("{}: {}", name.display(), circle.join(" → ")));
        }
    }
    assert!(
        circles.is_empty(),
        "files that import each other (move what both need to where both can use it):\n{}",
        circles.join("\n")
    );
}

#[test]
fn a_circle_is_found_and_groups_are_expanded() {
    let mut paths = crate_paths("use crate::{a::X, b::{c::Y, Z as W}};\nlet v = crate::d::f();");
    paths.sort();
    assert_eq!(paths, ["a::X", "b::Z", "b::c::Y", "d::f"]);
    let graph: BTreeMap<String, BTreeSet<String>> = [
        ("a", vec!["b"]),
        ("b", vec!["c"]),
        ("c", vec!["a"]),
        ("d", vec![]),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.into_iter().map(String::from).collect()))
    .collect();
    assert_eq!(find_circle(&graph).expect("a circle"), ["a", "b", "c", "a"]);
    let reexports = root_reexports("pub use report::gap::{Shrink, GapSummary};");
    let modules: BTreeSet<String> = ["report", "report::gap"].map(String::from).into();
    assert_eq!(
        resolve("Shrink", &modules, &reexports).as_deref(),
        Some("report::gap")
    );
}
