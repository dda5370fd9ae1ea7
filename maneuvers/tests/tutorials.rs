//! The tutorials' code is the project's code: every fenced block of `docs/*.md` whose info
//! string names a file (```` ```rust file=ubc-app/src/bin/square.rs ````) must appear in that
//! file verbatim, so what the tutorials show is what is compiled and run by the tests (the
//! example law and program have their own end-to-end tests in `arena/tests/`).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// `(file, block)` for every block of `markdown` that names a file.
fn file_blocks(markdown: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut lines = markdown.lines();
    while let Some(line) = lines.next() {
        let Some(info) = line.strip_prefix("```") else {
            continue;
        };
        let file = info
            .split_whitespace()
            .find_map(|w| w.strip_prefix("file="))
            .map(str::to_owned);
        let mut block = String::new();
        for l in lines.by_ref() {
            if l.starts_with("```") {
                break;
            }
            block.push_str(l);
            block.push('\n');
        }
        if let Some(f) = file {
            out.push((f, block));
        }
    }
    out
}

fn check(doc: &Path) -> usize {
    let text = std::fs::read_to_string(doc).unwrap();
    let blocks = file_blocks(&text);
    for (file, block) in &blocks {
        let source = std::fs::read_to_string(root().join(file))
            .unwrap_or_else(|e| panic!("{}: {file}: {e}", doc.display()));
        assert!(
            source.contains(block.as_str()),
            "{}: this block is not in {file} as it is:\n{block}",
            doc.display()
        );
    }
    blocks.len()
}

#[test]
fn tutorial_code_is_the_compiled_code() {
    let tutorial = |doc: &str, at_least: usize| {
        let n = check(&root().join(doc));
        assert!(n >= at_least, "{doc}: only {n} checked blocks");
    };
    tutorial("docs/writing-a-program.md", 5);
    tutorial("docs/writing-a-law.md", 12);
    // Any other page that names a file is held to it too.
    for entry in std::fs::read_dir(root().join("docs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "md") {
            check(&path);
        }
    }
}

#[test]
fn blocks_are_found() {
    let md = "text\n```rust file=a.rs\nfn a() {}\n```\n```sh\nls\n```\n";
    assert_eq!(
        file_blocks(md),
        vec![("a.rs".to_owned(), "fn a() {}\n".to_owned())]
    );
}
