//! The layering that ARCHITECTURE.md promises, checked on the source tree:
//!
//! - between crates, every arrow points down: a crate's `[dependencies]` name only crates of a
//!   lower layer (`msgs`, `model` <- `sim` <- `formats`, `viz` <- `bag` <- `nodes` <- `cli`);
//! - inside each crate, no module imports a module that imports it back, directly or through
//!   others: the graph of `crate::...`, `super::...` and `self::...` paths between the files of a
//!   crate has no cycle. Inside a crate, code names the module that defines an item, not a
//!   re-export at the crate root (which would count as an import of the root).
//!
//! The check reads the sources as text (comments and string literals stripped), so it needs no
//! compiler plugin and runs in milliseconds.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates of the workspace by directory, with their layer (a crate may use lower layers only).
const LAYERS: &[(&str, &str, u32)] = &[
    ("msgs", "volcal_msgs", 0),
    ("model", "volcal", 0),
    ("sim", "volcal_sim", 1),
    ("formats", "volcal_formats", 2),
    ("viz", "volcal_viz", 2),
    ("bag", "volcal_bag", 3),
    ("nodes", "volcal_nodes", 4),
    ("cli", "volcal_cli", 5),
];

#[test]
fn crates_depend_only_on_lower_layers() {
    let root = volcal_tests::repo_root();
    let layer: BTreeMap<&str, u32> = LAYERS.iter().map(|(_, name, l)| (*name, *l)).collect();
    let mut bad = Vec::new();
    for (dir, name, l) in LAYERS {
        let text = std::fs::read_to_string(root.join(dir).join("Cargo.toml")).unwrap();
        for dep in dependencies(&text) {
            if let Some(&dl) = layer.get(dep.as_str()) {
                if dl >= *l {
                    bad.push(format!("{name} (layer {l}) depends on {dep} (layer {dl})"));
                }
            }
        }
    }
    assert!(bad.is_empty(), "arrows that point up or sideways:\n{}", bad.join("\n"));
}

#[test]
fn no_module_imports_itself_back() {
    let root = volcal_tests::repo_root();
    let mut report = Vec::new();
    for (dir, name, _) in LAYERS {
        let src = root.join(dir).join("src");
        let modules = modules(&src);
        let graph = imports(&modules);
        let edges: usize = graph.values().map(|s| s.len()).sum();
        eprintln!("{name}: {} modules, {edges} imports between them", modules.len());
        for cycle in cycles(&graph) {
            report.push(format!("{name}: {} import each other in a circle", cycle.join(", ")));
        }
    }
    assert!(report.is_empty(), "modules that import themselves back:\n{}", report.join("\n"));
}

/// Names under `[dependencies]` (not dev- or build-dependencies) of a Cargo.toml.
fn dependencies(toml: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut inside = false;
    for line in toml.lines() {
        let t = line.trim();
        if t.starts_with('[') {
            inside = t == "[dependencies]";
            continue;
        }
        if inside && !t.is_empty() && !t.starts_with('#') {
            let key = t.split(['=', '.']).next().unwrap().trim();
            out.push(key.replace('-', "_"));
        }
    }
    out
}

/// The module path (`diagnose::locate`, `` for the crate root) of every file below `src`,
/// binaries (`main.rs`, `bin/`) excluded: they are crates of their own.
fn modules(src: &Path) -> BTreeMap<String, PathBuf> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(src).unwrap().to_string_lossy().replace('\\', "/");
            if p.is_dir() {
                if rel != "bin" {
                    stack.push(p);
                }
                continue;
            }
            let Some(stem) = rel.strip_suffix(".rs") else { continue };
            if stem == "main" {
                continue;
            }
            let m = match stem {
                "lib" => String::new(),
                s => s.strip_suffix("/mod").unwrap_or(s).replace('/', "::"),
            };
            out.insert(m, p);
        }
    }
    out
}

fn parent(m: &str) -> String {
    m.rsplit_once("::").map(|(p, _)| p.to_string()).unwrap_or_default()
}

fn join(a: &str, b: &str) -> String {
    if a.is_empty() {
        b.to_string()
    } else {
        format!("{a}::{b}")
    }
}

/// The longest module of `modules` that is a prefix of `path` (a `::` path without `crate`).
fn resolve(path: &str, modules: &BTreeMap<String, PathBuf>) -> String {
    let mut best = String::new();
    let mut cur = String::new();
    for seg in path.split("::") {
        cur = join(&cur, seg);
        if modules.contains_key(&cur) {
            best = cur.clone();
        }
    }
    best
}

/// Module -> modules it names through `crate::`, `super::`, `self::` or submodule paths (one level of
/// `use crate::{a, b::c}` braces included). Its inline test module (from `#[cfg(test)]` on,
/// where `super` is the module itself) counts as itself. Declaring a submodule (`mod x;`) is not
/// an import.
fn imports(modules: &BTreeMap<String, PathBuf>) -> BTreeMap<String, BTreeSet<String>> {
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (m, file) in modules {
        let code = strip(&std::fs::read_to_string(file).unwrap());
        let (main, tests) = code.split_at(code.find("#[cfg(test)]").unwrap_or(code.len()));
        let mut targets = BTreeSet::new();
        for (text, here) in [(main, m.clone()), (tests, join(m, "tests"))] {
            for t in referenced(text, &here, modules) {
                if &t != m {
                    targets.insert(t);
                }
            }
        }
        g.insert(m.clone(), targets);
    }
    g
}

/// Modules named by the paths in `code`, read as the body of module `here`.
fn referenced(code: &str, here: &str, modules: &BTreeMap<String, PathBuf>) -> BTreeSet<String> {
    let path_char = |c: char| c.is_alphanumeric() || c == '_' || c == ':';
    let mut paths: Vec<String> = Vec::new();
    let mut rest = code;
    while let Some(s) = rest.find(path_char) {
        let len = rest[s..].find(|c: char| !path_char(c)).unwrap_or(rest.len() - s);
        let run = &rest[s..s + len];
        let after = &rest[s + len..];
        if run.ends_with("::") && after.starts_with('{') {
            let close = after.find('}').unwrap_or(after.len());
            for item in after[1..close].split(',') {
                let item = item.trim();
                paths.push(format!("{run}{}", if item == "self" { "" } else { item }));
            }
        } else if run.contains("::") {
            paths.push(run.to_string());
        }
        rest = after;
    }
    let mut targets = BTreeSet::new();
    for path in paths {
        let segs: Vec<&str> = path.trim_end_matches(':').split("::").collect();
        let (base, tail) = match segs[0] {
            "crate" => (String::new(), &segs[1..]),
            "self" => (here.to_string(), &segs[1..]),
            "super" => {
                let ups = segs.iter().take_while(|s| **s == "super").count();
                ((0..ups).fold(here.to_string(), |b, _| parent(&b)), &segs[ups..])
            }
            // A path through a submodule of this one (`catalogue::directions`).
            child if modules.contains_key(&join(here, child)) => (here.to_string(), &segs[..]),
            _ => continue,
        };
        targets.insert(resolve(&tail.iter().fold(base, |acc, s| join(&acc, s)), modules));
    }
    targets
}

/// Source without comments, string and char literals (so that docs and messages naming paths
/// do not count as imports).
fn strip(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = String::with_capacity(s.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'/' && b.get(i + 1) == Some(&b'/') {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i] == b'/' && b.get(i + 1) == Some(&b'*') {
            i += 2;
            while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                i += 1;
            }
            i += 2;
        } else if b[i] == b'r'
            && (b.get(i + 1) == Some(&b'"') || b.get(i + 1) == Some(&b'#'))
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'))
        {
            // Raw string r"..." or r#"..."#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&b'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&b'"') {
                out.push(b[i] as char);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == b'"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&b'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            out.push_str("\"\"");
            i = j;
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                if b[i] == b'\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
            out.push_str("\"\"");
        } else if b[i] == b'\'' && b.get(i + 2) == Some(&b'\'') {
            i += 3;
        } else if b[i] == b'\'' && b.get(i + 1) == Some(&b'\\') {
            i += 2;
            while i < b.len() && b[i] != b'\'' {
                i += 1;
            }
            i += 1;
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// The modules that import each other in a circle: the strongly connected components of more
/// than one module (Tarjan).
fn cycles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct T<'a> {
        g: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    impl<'a> T<'a> {
        fn visit(&mut self, v: &'a str) {
            self.index.insert(v, self.next);
            self.low.insert(v, self.next);
            self.next += 1;
            self.stack.push(v);
            self.on.insert(v);
            for w in self.g.get(v).into_iter().flatten() {
                let w = w.as_str();
                if !self.g.contains_key(w) {
                    continue;
                }
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let lw = self.low[w];
                    let lv = self.low.get_mut(v).unwrap();
                    *lv = (*lv).min(lw);
                } else if self.on.contains(w) {
                    let iw = self.index[w];
                    let lv = self.low.get_mut(v).unwrap();
                    *lv = (*lv).min(iw);
                }
            }
            if self.low[v] == self.index[v] {
                let mut comp = Vec::new();
                loop {
                    let w = self.stack.pop().unwrap();
                    self.on.remove(w);
                    comp.push(w.to_string());
                    if w == v {
                        break;
                    }
                }
                if comp.len() > 1 {
                    comp.sort();
                    self.out
                        .push(comp.into_iter().map(|m| if m.is_empty() { "(crate root)".into() } else { m }).collect());
                }
            }
        }
    }
    let mut t = T {
        g,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in g.keys() {
        if !t.index.contains_key(v.as_str()) {
            t.visit(v);
        }
    }
    t.out
}

/// `cargo run --release -- demo` and `cargo test --release --workspace` (README) share one set
/// of compiled dependencies only if every dependency they share is built with the same features.
/// The test-only crates (proptest, criterion) switch some on; `cli/Cargo.toml` asks for them too.
/// This compares the two resolutions as `cargo tree` prints them.
#[test]
fn the_tool_and_the_tests_build_dependencies_with_the_same_features() {
    let root = volcal_tests::repo_root();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let tree = |args: &[&str]| -> BTreeSet<String> {
        let out = std::process::Command::new(&cargo)
            .current_dir(&root)
            .args(["tree", "--offline", "--prefix", "none", "-f", "{p} [{f}]"])
            .args(args)
            .output()
            .expect("cargo tree runs");
        assert!(out.status.success(), "cargo tree {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| l.trim_end_matches(" (*)").to_string())
            .filter(|l| !l.is_empty() && !l.contains(&*root.to_string_lossy()))
            .collect()
    };
    let run = tree(&["-p", "volcal_cli", "-e", "normal,build"]);
    let test = tree(&["--workspace", "-e", "normal,build,dev"]);
    let package = |l: &String| l.split(" [").next().unwrap().to_string();
    let shared: BTreeSet<String> = run.iter().map(package).collect();
    let differ: Vec<&String> = run.symmetric_difference(&test).filter(|l| shared.contains(&package(l))).collect();
    assert!(
        differ.is_empty(),
        "dependencies built with other features by `cargo test --workspace` than by `cargo run` \
         (add the features to cli/Cargo.toml's unification list):\n{}",
        differ.iter().map(|s| s.as_str()).collect::<Vec<_>>().join("\n")
    );
    eprintln!("{} dependencies of the tool, built alike by both commands", shared.len());
}
