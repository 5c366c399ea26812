//! The crate's size rules, checked: no `src/` file over [`MAX_FILE_LINES`] lines unless
//! its opening `//!` comment names its one concept after [`ONE_CONCEPT_MARKER`], and no
//! function body over [`MAX_FN_LINES`] lines but the ones listed here by name.
//!
//! Function bodies are found in the text with comments and literals blanked
//! ([`super::strip`]): every `fn <name>` whose signature opens a `{` (not a `;`), to the
//! matching `}`; a body's length is the lines strictly between the two braces. Nested
//! functions count on their own and inside their parent.

use std::collections::BTreeSet;

/// A file longer than this must say which one concept it is.
const MAX_FILE_LINES: usize = 700;

/// A function body longer than this fails, unless listed below.
const MAX_FN_LINES: usize = 100;

/// The marker that opens the line of a long file's `//!` comment naming its one concept,
/// e.g. `//! One concept: pycocotools' COCOeval, step for step.`
const ONE_CONCEPT_MARKER: &str = "One concept:";

/// Long functions allowed for good, as (file, function): the pickle interpreter's opcode
/// table is one `match` with an arm per opcode, read best in one place.
const LONG_FUNCTIONS_ALLOWED: &[(&str, &str)] = &[("src/weights/pickle.rs", "run")];

/// Long functions not split yet, as (file, function). Like the import lists in
/// `architecture.rs` this list only shrinks: a long function not listed fails, and so does
/// a listed one that is gone or short (remove its entry). Empty since issue 40's third
/// session split the YOLO ONNX graph writer and the ultralytics weights reader.
const LONG_FUNCTIONS_PENDING: &[(&str, &str)] = &[];

/// Long files without the marker that wait for a split; empty since engineer D split
/// `src/train/trainer.rs`. Shrinks like the list above.
const LONG_FILES_PENDING: &[&str] = &[];

/// Every function of `text` with its body's length in lines: (name, lines).
pub(super) fn function_lengths(text: &str) -> Vec<(String, usize)> {
    let s: Vec<char> = super::strip(text).chars().collect();
    let line_at = |i: usize| s[..i].iter().filter(|&&c| c == '\n').count();
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut out = Vec::new();
    let mut i = 0;
    while i + 2 < s.len() {
        let word_start = i == 0 || !ident(s[i - 1]);
        if !(word_start && s[i] == 'f' && s[i + 1] == 'n' && s[i + 2].is_whitespace()) {
            i += 1;
            continue;
        }
        let mut j = i + 2;
        while j < s.len() && s[j].is_whitespace() {
            j += 1;
        }
        let name_start = j;
        while j < s.len() && ident(s[j]) {
            j += 1;
        }
        if j == name_start {
            // `fn(…)`: a function pointer type.
            i = j;
            continue;
        }
        let name: String = s[name_start..j].iter().collect();
        // The body's `{`, or the `;` of a declaration; a `;` inside brackets is an array
        // type (`[usize; 2]`).
        let mut brackets = 0i32;
        while j < s.len() && !(brackets == 0 && (s[j] == '{' || s[j] == ';')) {
            match s[j] {
                '(' | '[' => brackets += 1,
                ')' | ']' => brackets -= 1,
                _ => {}
            }
            j += 1;
        }
        if j < s.len() && s[j] == '{' {
            let open = j;
            let mut depth = 0usize;
            while j < s.len() {
                match s[j] {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    _ => {}
                }
                j += 1;
            }
            let close = j.min(s.len() - 1);
            out.push((name, line_at(close).saturating_sub(line_at(open) + 1)));
        }
        i = name_start;
    }
    out
}

/// Whether the opening `//!` comment of `text` has a line `//! One concept: <name>`.
pub(super) fn names_one_concept(text: &str) -> bool {
    text.lines()
        .take_while(|l| l.starts_with("//!"))
        .filter_map(|l| {
            l.trim_start_matches("//!")
                .trim()
                .strip_prefix(ONE_CONCEPT_MARKER)
        })
        .any(|name| name.trim().len() >= 3)
}

#[test]
fn no_long_file_without_its_one_concept() {
    let mut long = BTreeSet::new();
    for f in super::source_files_with_lib() {
        let lines = f.text.lines().count();
        if lines > MAX_FILE_LINES && !names_one_concept(&f.text) {
            long.insert(format!("{} ({lines} lines)", f.rel));
        }
    }
    let found: BTreeSet<String> = long
        .iter()
        .map(|l| l.split(' ').next().expect("a name").to_string())
        .collect();
    let pending: BTreeSet<String> = LONG_FILES_PENDING.iter().map(|s| s.to_string()).collect();
    let new: Vec<String> = long
        .iter()
        .filter(|l| !pending.contains(l.split(' ').next().expect("a name")))
        .cloned()
        .collect();
    let gone: Vec<String> = pending.difference(&found).cloned().collect();
    assert!(
        new.is_empty() && gone.is_empty(),
        "{}\n{}",
        super::report(
            &format!(
                "files over {MAX_FILE_LINES} lines whose opening comment has no `//! {ONE_CONCEPT_MARKER} <name>` line (split them, or name the one concept)"
            ),
            &new
        ),
        super::report(
            "LONG_FILES_PENDING entries that are short or named now (remove them)",
            &gone
        )
    );
}

#[test]
fn no_long_function_but_the_listed_ones() {
    let mut long: Vec<((String, String), usize)> = Vec::new();
    for f in super::source_files_with_lib() {
        for (name, n) in function_lengths(&f.text) {
            if n > MAX_FN_LINES
                && !LONG_FUNCTIONS_ALLOWED.contains(&(f.rel.as_str(), name.as_str()))
            {
                long.push(((f.rel.clone(), name), n));
            }
        }
    }
    let found: BTreeSet<(String, String)> = long.iter().map(|(k, _)| k.clone()).collect();
    let pending: BTreeSet<(String, String)> = LONG_FUNCTIONS_PENDING
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    let new: Vec<String> = long
        .iter()
        .filter(|(k, _)| !pending.contains(k))
        .map(|((file, name), n)| format!("{file} {name} ({n} lines)"))
        .collect();
    let gone: Vec<String> = pending
        .difference(&found)
        .map(|(a, b)| format!("{a} {b}"))
        .collect();
    assert!(
        new.is_empty() && gone.is_empty(),
        "{}\n{}",
        super::report(
            &format!("functions over {MAX_FN_LINES} lines not in LONG_FUNCTIONS_PENDING"),
            &new
        ),
        super::report(
            "LONG_FUNCTIONS_PENDING entries that are short or gone now (remove them)",
            &gone
        )
    );
}

#[test]
fn the_size_reader_counts_bodies_and_reads_the_marker() {
    let text = "//! A file.\n//! One concept: the thing.\n\nfn a() {\n    let s = \"}\";\n    x;\n}\n\
                trait T { fn b(&self); }\nimpl T for () {\n    fn b(&self) {}\n}\n\
                fn c(f: fn(u8) -> u8, g: [u8; 2]) -> u8 {\n    // }\n    fn d() {\n        y;\n    }\n    f(0)\n}\n";
    let got = function_lengths(text);
    assert_eq!(
        got,
        [
            ("a".to_string(), 2),
            ("b".to_string(), 0),
            ("c".to_string(), 5),
            ("d".to_string(), 1)
        ]
    );
    assert!(names_one_concept(text));
    assert!(!names_one_concept("//! A file.\n//! One concept:\n"));
    assert!(!names_one_concept(
        "//! A file.\n\n//! One concept: late.\n"
    ));
}
