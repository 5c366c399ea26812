//! The documentation's promises against the binary: every `chicktrain <cmd> [<sub>]` that
//! README.md, BENCHMARKS.md or a page under docs/ names in code exists (its `--help`
//! succeeds) and accepts every `--flag` written after it, and every relative link of those
//! pages (file and `#anchor`) resolves in the repository. Documentation drifts silently
//! otherwise: a renamed flag or a moved page would only show when a user tries it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod common;
use common::run;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md, BENCHMARKS.md and every docs/*.md, as (path relative to the root, text).
fn pages() -> Vec<(PathBuf, String)> {
    let mut paths = vec![PathBuf::from("README.md"), PathBuf::from("BENCHMARKS.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/ must exist")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .map(|p| p.strip_prefix(root()).unwrap().to_path_buf())
        .collect();
    docs.sort();
    assert!(!docs.is_empty(), "docs/ has no .md page");
    paths.extend(docs);
    paths
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(root().join(&p))
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, text)
        })
        .collect()
}

/// The code of a Markdown page: fenced blocks line by line, and the inline `code` spans
/// of the prose, read per paragraph (a span may wrap onto the next line; a table cell's
/// backquoted command is one span).
fn code_snippets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut fenced = false;
    let mut paragraph = String::new();
    fn spans(paragraph: &mut String, out: &mut Vec<String>) {
        let mut parts = paragraph.split('`');
        parts.next(); // text before the first backquote
        while let Some(code) = parts.next() {
            out.push(code.replace('\n', " "));
            parts.next(); // text between spans
        }
        paragraph.clear();
    }
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            spans(&mut paragraph, &mut out);
            fenced = !fenced;
        } else if fenced {
            out.push(line.to_string());
        } else if line.trim().is_empty() || line.starts_with('|') {
            spans(&mut paragraph, &mut out);
            paragraph.push_str(line);
            spans(&mut paragraph, &mut out);
        } else {
            paragraph.push_str(line);
            paragraph.push('\n');
        }
    }
    spans(&mut paragraph, &mut out);
    out
}

fn is_word(t: &str) -> bool {
    t.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && t.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-')
}

/// Every command a snippet runs: `chicktrain` followed by up to two lowercase words (the
/// command and a subcommand such as `bench models`), with the `--flags` written after it
/// up to the end of the snippet or the next shell separator.
fn commands(snippet: &str) -> Vec<(Vec<String>, Vec<String>)> {
    let tokens: Vec<&str> = snippet.split_whitespace().collect();
    let mut found = Vec::new();
    for (i, t) in tokens.iter().enumerate() {
        let bin = t.rsplit('/').next().unwrap();
        // `--bin target/release/chicktrain` hands the binary to a script: not a command.
        if bin != "chicktrain" || (i > 0 && tokens[i - 1] == "--bin") {
            continue;
        }
        let mut words = Vec::new();
        let mut j = i + 1;
        while j < tokens.len() && words.len() < 2 && is_word(tokens[j]) {
            words.push(tokens[j].to_string());
            j += 1;
        }
        let mut flags = Vec::new();
        while j < tokens.len() && !matches!(tokens[j], "&&" | "|" | ";" | "#" | "=") {
            // `[--split val\|test]`, `--no-train\|--train-only`, `--set K=V`
            for piece in tokens[j].split(['|', '\\']) {
                let flag = piece.split('=').next().unwrap();
                let name = flag.trim_matches(|c: char| !(c.is_ascii_alphanumeric() || c == '-'));
                if name.len() > 2 && name.starts_with("--") && is_word(&name[2..]) {
                    flags.push(name.to_string());
                }
            }
            j += 1;
        }
        found.push((words, flags));
    }
    found
}

#[test]
fn every_command_the_docs_name_exists_with_its_flags() {
    // command words -> (flags named with it, first page naming it)
    let mut named: BTreeMap<Vec<String>, (BTreeSet<String>, String)> = BTreeMap::new();
    for (page, text) in pages() {
        for snippet in code_snippets(&text) {
            for (words, flags) in commands(&snippet) {
                let e = named
                    .entry(words)
                    .or_insert_with(|| (BTreeSet::new(), page.display().to_string()));
                e.0.extend(flags);
            }
        }
    }
    let readme_words: BTreeSet<String> =
        code_snippets(&std::fs::read_to_string(root().join("README.md")).unwrap())
            .iter()
            .flat_map(|s| commands(s))
            .filter_map(|(w, _)| w.first().cloned())
            .collect();
    for cmd in [
        "eval", "predict", "export", "render", "convert", "bench", "sweep",
    ] {
        assert!(
            readme_words.contains(cmd),
            "README.md names no `chicktrain {cmd}`"
        );
    }
    assert!(
        named.len() >= 15,
        "only {} commands found: {named:?}",
        named.len()
    );
    let mut failures = Vec::new();
    for (words, (flags, page)) in &named {
        let mut args: Vec<&str> = words.iter().map(String::as_str).collect();
        args.push("--help");
        let out = run(&args);
        let help = String::from_utf8_lossy(&out.stdout).to_string();
        if !out.status.success() {
            failures.push(format!(
                "{page}: `chicktrain {}` failed: {}",
                args.join(" "),
                String::from_utf8_lossy(&out.stderr)
            ));
            continue;
        }
        for f in flags {
            if !help.contains(&format!("{f} ")) && !help.contains(&format!("{f}\n")) {
                failures.push(format!(
                    "{page}: `chicktrain {}` has no flag {f}",
                    words.join(" ")
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// GitHub's anchor of a heading: lower case, spaces to hyphens, punctuation dropped.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

fn anchors(text: &str) -> BTreeSet<String> {
    let mut fenced = false;
    let mut out = BTreeSet::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced && line.starts_with('#') {
            out.insert(anchor(line.trim_start_matches('#')));
        }
    }
    out
}

/// Every `](target)` of a page's prose (not inside code).
fn links(text: &str) -> Vec<String> {
    let mut fenced = false;
    let mut out = Vec::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        let mut rest = line;
        while let Some(k) = rest.find("](") {
            let after = &rest[k + 2..];
            let Some(end) = after.find(')') else { break };
            out.push(after[..end].to_string());
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_of_the_docs_resolves() {
    let pages = pages();
    let mut checked = 0;
    let mut failures = Vec::new();
    for (page, text) in &pages {
        for target in links(text) {
            if target.starts_with("http://") || target.starts_with("https://") {
                continue;
            }
            let (file, frag) = match target.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (target.as_str(), None),
            };
            let dir = page.parent().unwrap_or(Path::new(""));
            let path = if file.is_empty() {
                root().join(page)
            } else {
                root().join(dir).join(file)
            };
            checked += 1;
            if !path.exists() {
                failures.push(format!("{}: {target} does not exist", page.display()));
                continue;
            }
            if let Some(a) = frag {
                let text = std::fs::read_to_string(&path).unwrap_or_default();
                if !anchors(&text).contains(a) {
                    failures.push(format!("{}: {target}: no heading #{a}", page.display()));
                }
            }
        }
    }
    assert!(checked >= 30, "only {checked} links checked");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn anchors_follow_githubs_rule() {
    assert_eq!(
        anchor(" Test-time augmentation (`--augment`)"),
        "test-time-augmentation---augment"
    );
    assert_eq!(
        anchor("Model bench: variants × input sizes"),
        "model-bench-variants--input-sizes"
    );
    assert_eq!(anchor("The paper's experiment"), "the-papers-experiment");
}

#[test]
fn commands_are_read_with_their_flags() {
    let c = commands("RAYON_NUM_THREADS=1 target/release/chicktrain bench models --variants yolo-n --sizes 256 && ls");
    assert_eq!(
        c,
        vec![(
            vec!["bench".to_string(), "models".to_string()],
            vec!["--variants".to_string(), "--sizes".to_string()]
        )]
    );
    let c = commands("chicktrain --config quickstart.toml --set train.epochs=5");
    assert_eq!(c[0].0, Vec::<String>::new());
    assert_eq!(c[0].1, vec!["--config".to_string(), "--set".to_string()]);
    assert!(commands("chicktrain's own engines").is_empty());
    assert_eq!(
        code_snippets("a `x` b `chicktrain eval` c\n```sh\nchicktrain sweep\n```\n"),
        vec!["x", "chicktrain eval", "chicktrain sweep"]
    );
}
