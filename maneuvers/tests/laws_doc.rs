//! `docs/maneuvers.md` section 4.6 is the reference of every registered law, generated from
//! the registration list: this test fails when the two differ (a law added, a parameter
//! changed). `UPDATE_DOCS=1 cargo test -p maneuvers --test laws_doc` rewrites the section.

use std::path::PathBuf;

use maneuvers::reference::{write_markdown, BEGIN_MARKER, END_MARKER};

#[test]
fn the_laws_reference_in_the_docs_is_the_registration_list() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/maneuvers.md");
    let doc = std::fs::read_to_string(&path).expect("docs/maneuvers.md");
    let begin = doc.find(BEGIN_MARKER).expect("begin marker") + BEGIN_MARKER.len();
    let end = doc.find(END_MARKER).expect("end marker");
    assert!(begin <= end, "markers out of order");
    let mut generated = String::new();
    write_markdown(&mut generated).unwrap();
    let expected = format!("\n\n{generated}\n");
    if doc[begin..end] == expected {
        return;
    }
    if std::env::var_os("UPDATE_DOCS").is_some_and(|v| v == "1") {
        let updated = format!("{}{expected}{}", &doc[..begin], &doc[end..]);
        std::fs::write(&path, updated).expect("writing docs/maneuvers.md");
        eprintln!("rewrote the laws reference in {}", path.display());
        return;
    }
    panic!(
        "docs/maneuvers.md section 4.6 does not list the registered laws as they are; run \
         `UPDATE_DOCS=1 cargo test -p maneuvers --test laws_doc` and commit the result.\n\
         expected:\n{expected}"
    );
}
