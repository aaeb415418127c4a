//! Dependencies between the top-level modules of `src/` point down the layers of ARCHITECTURE.md:
//! a module names only modules of lower layers. The check reads the sources: every
//! `crate::<module>` path (and `use crate::{a, b}` group) outside test code is an edge, and a
//! use of the prelude counts as an edge to the module of each prelude item the file names.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers, bottom first. A module may name only modules of a strictly lower layer.
const LAYERS: &[&[&str]] = &[
    &["random"],
    &["geometry"],
    &["components"],
    &["resources"],
    &["gpu"],
    &["systems", "amplify"],
    &["plugins"],
    &["simulation"],
    &["io", "commands"],
    &["viewer"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

/// Removes comments, string and char literals (so that a path in a doc comment or a message is
/// not an edge), and `#[cfg(test)]` items (test code may use anything).
fn strip(source: &str) -> String {
    let b = source.as_bytes();
    let mut out = String::with_capacity(source.len());
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            let end = b[i + 2..]
                .windows(2)
                .position(|w| w == b"*/")
                .map_or(b.len(), |e| i + 2 + e + 2);
            i = end;
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if b[i..].starts_with(b"#[cfg(test)]") {
            // Skip the attribute and the item after it (up to its matching closing brace, or
            // its semicolon for `mod tests;`).
            i += "#[cfg(test)]".len();
            let mut depth = 0usize;
            while i < b.len() {
                match b[i] {
                    b'{' => depth += 1,
                    b'}' => {
                        depth = depth.saturating_sub(1);
                        if depth == 0 {
                            i += 1;
                            break;
                        }
                    }
                    b';' if depth == 0 => {
                        i += 1;
                        break;
                    }
                    _ => {}
                }
                i += 1;
            }
        } else {
            // Bytes, not chars: a multi-byte character (in a char literal, say) is copied
            // byte by byte as Latin-1, which no identifier contains.
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

fn identifiers(code: &str) -> BTreeSet<String> {
    code.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

/// The names the prelude re-exports, each with the top-level module it comes from.
fn prelude_names(lib_rs: &str) -> BTreeMap<String, String> {
    let mut names = BTreeMap::new();
    let Some(start) = lib_rs.find("pub mod prelude") else {
        return names;
    };
    for stmt in lib_rs[start..].split(';') {
        let Some(at) = stmt.find("pub use crate::") else {
            continue;
        };
        let path = &stmt[at + "pub use crate::".len()..];
        let module: String = path
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let items = match (path.find('{'), path.rfind('}')) {
            (Some(a), Some(b)) => path[a + 1..b].to_string(),
            _ => path.rsplit("::").next().unwrap_or("").to_string(),
        };
        for item in items.split(',') {
            let name = item.trim().rsplit("::").next().unwrap_or("").trim();
            if !name.is_empty() && name != "self" {
                names.insert(name.to_string(), module.clone());
            }
        }
    }
    names
}

/// Edges `(from, to) -> files` between the top-level modules of the tree at `src`, given as
/// `(path relative to src, source)` pairs.
fn edges(
    files: &[(PathBuf, String)],
    prelude: &BTreeMap<String, String>,
) -> BTreeMap<(String, String), BTreeSet<String>> {
    let mut out: BTreeMap<(String, String), BTreeSet<String>> = BTreeMap::new();
    for (rel, source) in files {
        let Some(first) = rel.components().next() else {
            continue;
        };
        let top = first
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_string();
        if top == "lib" || top == "main" || top == "cli" {
            continue;
        }
        let code = strip(source);
        let mut named: BTreeSet<String> = BTreeSet::new();
        for (at, _) in code.match_indices("crate::") {
            let rest = &code[at + "crate::".len()..];
            if let Some(group) = rest.strip_prefix('{') {
                let body = group.split('}').next().unwrap_or("");
                for part in body.split(',') {
                    let m: String = part
                        .trim()
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    named.insert(m);
                }
            } else {
                let m: String = rest
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                named.insert(m);
            }
        }
        if named.remove("prelude") {
            for id in identifiers(&code) {
                if let Some(m) = prelude.get(&id) {
                    named.insert(m.clone());
                }
            }
        }
        for m in named {
            if m != top && layer_of(&m).is_some() {
                out.entry((top.clone(), m))
                    .or_default()
                    .insert(rel.display().to_string());
            }
        }
    }
    out
}

/// Every edge that does not point to a strictly lower layer, as a message.
fn violations(edges: &BTreeMap<(String, String), BTreeSet<String>>) -> Vec<String> {
    let mut bad = Vec::new();
    for ((from, to), files) in edges {
        let (Some(a), Some(b)) = (layer_of(from), layer_of(to)) else {
            bad.push(format!("`{from}` or `{to}` has no layer in LAYERS"));
            continue;
        };
        if b >= a {
            bad.push(format!(
                "`{from}` (layer {a}) names `{to}` (layer {b}) in {}",
                files.iter().cloned().collect::<Vec<_>>().join(", ")
            ));
        }
    }
    bad
}

fn rust_files(dir: &Path, root: &Path, out: &mut Vec<(PathBuf, String)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.filter_map(Result::ok).map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, root, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            // File-level test modules (`#[cfg(test)] mod tests;`) may use anything.
            if p.file_name().is_some_and(|n| n == "tests.rs") {
                continue;
            }
            let rel = p.strip_prefix(root).unwrap_or(&p).to_path_buf();
            let source = std::fs::read_to_string(&p).unwrap_or_default();
            out.push((rel, source));
        }
    }
}

#[test]
fn dependencies_point_down_the_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib = std::fs::read_to_string(src.join("lib.rs")).expect("src/lib.rs");
    let prelude = prelude_names(&lib);
    assert!(
        prelude.get("Simulation").map(String::as_str) == Some("simulation")
            && prelude.get("Crust").map(String::as_str) == Some("resources"),
        "the prelude parser found {prelude:?}"
    );
    // Every top-level module has a layer.
    for entry in std::fs::read_dir(&src).expect("src/") {
        let p = entry.expect("entry").path();
        let name = p.file_stem().map(|s| s.to_string_lossy().to_string());
        let Some(name) = name else { continue };
        if ["lib", "main", "cli"].contains(&name.as_str()) {
            continue;
        }
        assert!(
            layer_of(&name).is_some(),
            "src/{name} has no layer: add it to LAYERS here and to ARCHITECTURE.md"
        );
    }
    let mut files = Vec::new();
    rust_files(&src, &src, &mut files);
    assert!(files.len() > 50, "found only {} source files", files.len());
    let e = edges(&files, &prelude);
    assert!(
        e.contains_key(&("systems".to_string(), "gpu".to_string())),
        "the scan found no systems -> gpu edge; is it reading the sources? {:?}",
        e.keys().collect::<Vec<_>>()
    );
    let bad = violations(&e);
    assert!(bad.is_empty(), "upward dependencies:\n{}", bad.join("\n"));
}

#[test]
fn a_planted_upward_import_is_caught() {
    let lib = "pub mod prelude {\n    pub use crate::simulation::{SimError, Simulation};\n    pub use crate::resources::{Crust};\n}\n";
    let prelude = prelude_names(lib);
    let file = |path: &str, source: &str| (PathBuf::from(path), source.to_string());
    let clean = vec![
        file(
            "systems/erosion.rs",
            "use crate::gpu::erosion::ErosionRates;\n",
        ),
        // Test code and comments do not count.
        file(
            "gpu/erosion.rs",
            "// see crate::systems::erosion\nfn f() {}\n#[cfg(test)]\nmod tests {\n    use crate::simulation::Simulation;\n}\n",
        ),
        file(
            "plugins/x.rs",
            "use crate::prelude::*;\nfn f(c: &Crust) {}\n",
        ),
    ];
    assert!(violations(&edges(&clean, &prelude)).is_empty());
    for planted in [
        file(
            "gpu/erosion.rs",
            "pub use crate::systems::erosion::erosion_cpu;\n",
        ),
        file("resources/mod.rs", "use crate::{geometry, plugins};\n"),
        file(
            "plugins/x.rs",
            "use crate::prelude::*;\nfn f(s: &mut Simulation) {}\n",
        ),
    ] {
        let mut files = clean.clone();
        files.push(planted.clone());
        let bad = violations(&edges(&files, &prelude));
        assert_eq!(
            bad.len(),
            1,
            "{} was not caught: {bad:?}",
            planted.0.display()
        );
    }
}
