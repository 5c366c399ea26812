//! The crate's design, checked: the import graph of `src/**/*.rs` has no circle among
//! files, no top-level module imports from a layer above its own, and the size rules hold
//! (no file over 700 lines unless it names its one concept, no function over 100 lines
//! but those listed by name: [`sizes`], in `tests/architecture/sizes.rs`).
//!
//! The graph is read from the source text, not from the compiler: every path that
//! starts with `crate::`, `super::` or `self::` (in `use` trees, group braces expanded,
//! and inline in code), and every `use` whose first segment names a child module, is
//! resolved to the file that defines the longest matching module prefix. Comments and
//! string literals are skipped, and `mod name { … }` blocks inside a file (tests) are
//! followed so that their `super::` means the file itself. `src/main.rs` is the binary,
//! a crate of its own; `src/lib.rs` only declares modules and is left out.
//!
//! The layer table [`LAYERS`] is the one place the layering is written down in code;
//! `docs/architecture.md` draws the same table and [`doc_table_matches_layers`] keeps
//! the two equal. Needs only `std`: no Python, network or build of the crate's code.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The size rules: long files name their one concept, long functions are listed.
#[path = "architecture/sizes.rs"]
mod sizes;

/// Layers from the bottom up: a top-level module may import from its own row and the
/// rows before it, never from a row after it. Within a row the module graph must still
/// be acyclic (checked separately).
const LAYERS: &[(&str, &[&str])] = &[
    ("foundation", &["util", "weights", "annotations"]),
    ("models", &["model"]),
    ("config", &["config"]),
    ("renderer", &["render"]),
    ("loader", &["data"]),
    ("evaluator", &["eval"]),
    ("inference", &["infer"]),
    ("export", &["export"]),
    ("trainer", &["train"]),
    ("on top", &["bench", "experiments", "commands"]),
];

/// Circles among files that are tolerated, each as its sorted member list (one strongly
/// connected component). Empty since issue 40 removed the last eight; kept so that a
/// circle met mid-refactor is listed by name rather than the test switched off. The list
/// only shrinks: a circle not listed fails the test, and so does a listed one that is
/// gone (remove its entry when you break it).
const ALLOWED_FILE_CYCLES: &[&[&str]] = &[];

/// Imports from a lower layer to a higher one that are tolerated, as (from file, to
/// file); empty since `config::Randomize` left the renderer. Shrinks like
/// [`ALLOWED_FILE_CYCLES`].
const ALLOWED_UPWARD: &[(&str, &str)] = &[];

/// A file of the crate and the module path it defines (`src/a/b.rs` and `src/a/b/mod.rs`
/// both define `a::b`).
struct SourceFile {
    rel: String,
    module: Vec<String>,
    text: String,
}

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn collect(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            collect(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Every `src/**/*.rs` but `main.rs` and `lib.rs` (the import graph's files).
fn source_files() -> Vec<SourceFile> {
    read_sources(false)
}

/// Every `src/**/*.rs`, `main.rs` and `lib.rs` included (what the size rules read).
fn source_files_with_lib() -> Vec<SourceFile> {
    read_sources(true)
}

fn read_sources(with_roots: bool) -> Vec<SourceFile> {
    let src = src_dir();
    let mut paths = Vec::new();
    collect(&src, &mut paths);
    let mut files = Vec::new();
    for p in paths {
        let rel = p
            .strip_prefix(&src)
            .expect("under src")
            .to_string_lossy()
            .replace('\\', "/");
        if !with_roots && (rel == "main.rs" || rel == "lib.rs") {
            continue;
        }
        let stem = rel.trim_end_matches(".rs");
        let mut module: Vec<String> = stem.split('/').map(str::to_string).collect();
        if module.last().is_some_and(|m| m == "mod") {
            module.pop();
        }
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{rel}: {e}"));
        files.push(SourceFile {
            rel: format!("src/{rel}"),
            module,
            text,
        });
    }
    assert!(
        files.len() > 20,
        "found only {} files under src/",
        files.len()
    );
    files
}

/// The text with comments and the insides of string and char literals blanked out
/// (newlines kept), so that doc links and messages are not read as imports.
fn strip(text: &str) -> String {
    let b: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(b.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
        } else if c == 'r' && (next == Some('"') || next == Some('#')) && !ident_before(&b, i) {
            // Raw string r"…" or r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            out.push_str(&" ".repeat(j - i + 1));
            i = j + 1;
            while i < b.len() {
                if b[i] == '"' && (0..hashes).all(|k| b.get(i + 1 + k) == Some(&'#')) {
                    out.push_str(&" ".repeat(1 + hashes));
                    i += 1 + hashes;
                    break;
                }
                out.push(blank(b[i]));
                i += 1;
            }
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < b.len() {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' && (b.get(i + 2) == Some(&'\'') || next == Some('\\')) {
            // A char literal ('x' or '\n', '\''); a lifetime ('a) has no closing quote.
            out.push(' ');
            i += 1;
            if b.get(i) == Some(&'\\') {
                out.push(' ');
                i += 1;
            }
            while i < b.len() && b[i] != '\'' {
                out.push(' ');
                i += 1;
            }
            out.push(' ');
            i += 1;
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn ident_before(b: &[char], i: usize) -> bool {
    i > 0 && (b[i - 1].is_alphanumeric() || b[i - 1] == '_')
}

/// Tokens: identifiers, `::`, and single punctuation characters.
fn tokens(text: &str) -> Vec<String> {
    let b: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_alphanumeric() || c == '_' {
            let start = i;
            while i < b.len() && (b[i].is_alphanumeric() || b[i] == '_') {
                i += 1;
            }
            out.push(b[start..i].iter().collect());
        } else if c == ':' && b.get(i + 1) == Some(&':') {
            out.push("::".into());
            i += 2;
        } else if c.is_whitespace() {
            i += 1;
        } else {
            out.push(c.to_string());
            i += 1;
        }
    }
    out
}

/// Reads a use tree (or a plain path) starting at `t[i]`, appending each full path to
/// `out` with `prefix` in front. Returns the index after the tree.
fn read_tree(t: &[String], mut i: usize, prefix: &[String], out: &mut Vec<Vec<String>>) -> usize {
    let mut path = prefix.to_vec();
    loop {
        match t.get(i).map(String::as_str) {
            Some("{") => {
                i += 1;
                while i < t.len() && t[i] != "}" {
                    i = read_tree(t, i, &path, out);
                    if t.get(i).map(String::as_str) == Some(",") {
                        i += 1;
                    }
                }
                return i + 1;
            }
            Some("*") => {
                out.push(path);
                return i + 1;
            }
            Some(s) if is_ident(s) => {
                if s != "self" || path.is_empty() {
                    path.push(s.to_string());
                }
                i += 1;
                if t.get(i).map(String::as_str) == Some("::") {
                    i += 1;
                    continue;
                }
                if t.get(i).map(String::as_str) == Some("as") {
                    i += 2;
                }
                out.push(path);
                return i;
            }
            _ => {
                out.push(path);
                return i;
            }
        }
    }
}

fn is_ident(s: &str) -> bool {
    s.chars()
        .next()
        .is_some_and(|c| c.is_alphabetic() || c == '_')
}

/// The module paths one file refers to: (absolute module path of the referring scope,
/// referenced path as written), resolved to absolute crate paths.
fn references(file: &SourceFile, modules: &BTreeSet<Vec<String>>) -> Vec<Vec<String>> {
    let t = tokens(&strip(&file.text));
    let mut out = Vec::new();
    // Inline `mod name {` blocks: (name, brace depth at which it closes).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < t.len() {
        let tok = t[i].as_str();
        let scope: Vec<String> = file
            .module
            .iter()
            .cloned()
            .chain(inline.iter().map(|(n, _)| n.clone()))
            .collect();
        match tok {
            "{" => depth += 1,
            "}" => {
                depth = depth.saturating_sub(1);
                if inline.last().is_some_and(|(_, d)| *d == depth) {
                    inline.pop();
                }
            }
            "mod" if t.get(i + 2).map(String::as_str) == Some("{") => {
                inline.push((t[i + 1].clone(), depth));
                depth += 1;
                i += 3;
                continue;
            }
            "use" => {
                let mut paths = Vec::new();
                let end = read_tree(&t, i + 1, &[], &mut paths);
                for p in paths {
                    if let Some(abs) = absolute(&p, &scope, modules, true) {
                        out.push(abs);
                    }
                }
                i = end.max(i + 1);
                continue;
            }
            "crate" | "super" | "self"
                if t.get(i + 1).map(String::as_str) == Some("::")
                    && !(i > 0 && (t[i - 1] == "::" || t[i - 1] == "$")) =>
            {
                let mut paths = Vec::new();
                let end = read_tree(&t, i, &[], &mut paths);
                for p in paths {
                    if let Some(abs) = absolute(&p, &scope, modules, false) {
                        out.push(abs);
                    }
                }
                i = end.max(i + 1);
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// `path` as written inside module `scope`, made absolute; `None` for external crates.
fn absolute(
    path: &[String],
    scope: &[String],
    modules: &BTreeSet<Vec<String>>,
    in_use: bool,
) -> Option<Vec<String>> {
    let first = path.first()?;
    let mut base: Vec<String>;
    let mut rest = path;
    match first.as_str() {
        "crate" => {
            base = Vec::new();
            rest = &path[1..];
        }
        "super" | "self" => {
            base = scope.to_vec();
            while let Some(s) = rest.first() {
                match s.as_str() {
                    "super" => {
                        base.pop()?;
                    }
                    "self" => {}
                    _ => break,
                }
                rest = &rest[1..];
            }
        }
        _ if in_use => {
            // `use child::X` in the module that declares `child`.
            let mut child = scope.to_vec();
            child.push(first.clone());
            if !modules.contains(&child) {
                return None;
            }
            base = scope.to_vec();
        }
        _ => return None,
    }
    base.extend(rest.iter().cloned());
    Some(base)
}

/// The file that defines the longest module prefix of `path`.
fn resolve<'a>(path: &[String], by_module: &'a BTreeMap<Vec<String>, String>) -> Option<&'a str> {
    (1..=path.len())
        .rev()
        .find_map(|n| by_module.get(&path[..n]).map(String::as_str))
}

/// File → files it imports.
fn file_graph() -> BTreeMap<String, BTreeSet<String>> {
    let files = source_files();
    let by_module: BTreeMap<Vec<String>, String> = files
        .iter()
        .map(|f| (f.module.clone(), f.rel.clone()))
        .collect();
    let modules: BTreeSet<Vec<String>> = by_module.keys().cloned().collect();
    let mut graph = BTreeMap::new();
    for f in &files {
        let mut to = BTreeSet::new();
        for p in references(f, &modules) {
            if let Some(target) = resolve(&p, &by_module) {
                if target != f.rel {
                    to.insert(target.to_string());
                }
            }
        }
        graph.insert(f.rel.clone(), to);
    }
    graph
}

/// Strongly connected components with more than one member (Tarjan), each sorted.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        s.on_stack.insert(v);
        let graph = s.graph;
        for w in graph.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if s.on_stack.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                comp.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                s.out.push(comp);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out.sort();
    s.out
}

/// The top-level module a file belongs to (`src/train/x.rs` → `train`).
fn top(file: &str) -> &str {
    let rest = file.trim_start_matches("src/");
    rest.split('/')
        .next()
        .expect("non-empty")
        .trim_end_matches(".rs")
}

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|(_, ms)| ms.contains(&module))
}

fn report(title: &str, lines: &[String]) -> String {
    format!("{title} ({}):\n  {}", lines.len(), lines.join("\n  "))
}

#[test]
fn no_import_circle_among_files() {
    let graph = file_graph();
    let found: BTreeSet<Vec<String>> = cycles(&graph).into_iter().collect();
    let allowed: BTreeSet<Vec<String>> = ALLOWED_FILE_CYCLES
        .iter()
        .map(|c| c.iter().map(|s| s.to_string()).collect())
        .collect();
    let new: Vec<String> = found
        .difference(&allowed)
        .map(|c| c.join(" <-> "))
        .collect();
    let gone: Vec<String> = allowed
        .difference(&found)
        .map(|c| c.join(" <-> "))
        .collect();
    assert!(
        new.is_empty() && gone.is_empty(),
        "{}\n{}",
        report(
            "import circles among files not in ALLOWED_FILE_CYCLES",
            &new
        ),
        report(
            "ALLOWED_FILE_CYCLES entries that no longer exist (remove them)",
            &gone
        )
    );
}

#[test]
fn no_import_from_a_lower_layer_to_a_higher_one() {
    let graph = file_graph();
    let mut unknown = BTreeSet::new();
    let mut found = BTreeSet::new();
    for (from, tos) in &graph {
        let Some(lf) = layer_of(top(from)) else {
            unknown.insert(top(from).to_string());
            continue;
        };
        for to in tos {
            match layer_of(top(to)) {
                Some(lt) if lt > lf => {
                    found.insert((from.clone(), to.clone()));
                }
                Some(_) => {}
                None => {
                    unknown.insert(top(to).to_string());
                }
            }
        }
    }
    assert!(
        unknown.is_empty(),
        "top-level modules missing from LAYERS: {unknown:?}"
    );
    let allowed: BTreeSet<(String, String)> = ALLOWED_UPWARD
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    let fmt = |s: &BTreeSet<&(String, String)>| -> Vec<String> {
        s.iter().map(|(a, b)| format!("{a} -> {b}")).collect()
    };
    let new: BTreeSet<&(String, String)> = found.difference(&allowed).collect();
    let gone: BTreeSet<&(String, String)> = allowed.difference(&found).collect();
    assert!(
        new.is_empty() && gone.is_empty(),
        "{}\n{}",
        report("upward imports not in ALLOWED_UPWARD", &fmt(&new)),
        report(
            "ALLOWED_UPWARD entries that no longer exist (remove them)",
            &fmt(&gone)
        )
    );
}

#[test]
fn no_import_circle_among_top_level_modules() {
    let mut modules: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (from, tos) in file_graph() {
        let entry = modules.entry(top(&from).to_string()).or_default();
        for to in tos {
            if top(&to) != top(&from) {
                entry.insert(top(&to).to_string());
            }
        }
    }
    let found = cycles(&modules);
    assert!(
        found.is_empty(),
        "circles among top-level modules: {found:?}"
    );
}

#[test]
fn every_top_level_module_has_one_layer() {
    let mut seen = BTreeSet::new();
    for (_, ms) in LAYERS {
        for m in *ms {
            assert!(seen.insert(*m), "{m} is in two rows of LAYERS");
        }
    }
    let lib = std::fs::read_to_string(src_dir().join("lib.rs")).expect("src/lib.rs");
    let declared: BTreeSet<&str> = lib
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|m| m.trim_end_matches(';'))
        .collect();
    let listed: BTreeSet<&str> = seen.iter().copied().collect();
    assert_eq!(declared, listed, "lib.rs's modules and LAYERS differ");
}

/// The `| layer | modules |` table in `docs/architecture.md`, as rows of
/// (layer, [modules in backticks]).
fn doc_layers() -> Vec<(String, Vec<String>)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/architecture.md");
    let doc = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let start = doc
        .find("| layer | modules |")
        .expect("docs/architecture.md has no layer table");
    doc[start..]
        .lines()
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let modules = cells[2]
                .split('`')
                .skip(1)
                .step_by(2)
                .map(|m| m.trim_end_matches('/').to_string())
                .collect();
            (cells[1].to_string(), modules)
        })
        .collect()
}

#[test]
fn doc_table_matches_layers() {
    let code: Vec<(String, Vec<String>)> = LAYERS
        .iter()
        .map(|(l, ms)| (l.to_string(), ms.iter().map(|m| m.to_string()).collect()))
        .collect();
    assert_eq!(
        doc_layers(),
        code,
        "docs/architecture.md's layer table differs from LAYERS"
    );
}

#[test]
fn the_parser_reads_groups_super_and_inline_paths() {
    let mods: BTreeSet<Vec<String>> = [vec!["a"], vec!["a", "b"], vec!["c"], vec!["c", "d"]]
        .into_iter()
        .map(|m| m.into_iter().map(String::from).collect())
        .collect();
    let f = SourceFile {
        rel: "src/a/b.rs".into(),
        module: vec!["a".into(), "b".into()],
        text: "//! see [`crate::x`]\nuse crate::{c::{self, d::D}, a::A as Z};\n\
               fn f() { let s = \"crate::y\"; crate::c::d::g(); }\n\
               mod tests { use super::*; }\nuse super::Q;"
            .into(),
    };
    let got: Vec<String> = references(&f, &mods).iter().map(|p| p.join("::")).collect();
    assert_eq!(got, ["c", "c::d::D", "a::A", "c::d::g", "a::b", "a::Q"]);
}
