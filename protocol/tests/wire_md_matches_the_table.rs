//! `WIRE.md` is the spec other languages decode from; the Rust kinds come from `table.rs`.
//! The two must list the same kinds with the same body formats.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::BTreeMap;

use rig_protocol::Kind;

/// Rows `| kind | message | format | fields |` of WIRE.md's body table: kind → fixed format.
fn wire_md_formats() -> BTreeMap<u8, String> {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/WIRE.md")).unwrap();
    let bodies = text
        .split("\n## ")
        .find(|section| section.starts_with("Bodies"))
        .expect("WIRE.md has a `## Bodies` section");
    let mut rows = BTreeMap::new();
    for line in bodies.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // ["", kind, message, format, fields, ""]
        if cells.len() < 5 {
            continue;
        }
        let Ok(kind) = cells[1].parse::<u8>() else {
            continue;
        };
        let format = cells[3].split('`').nth(1).unwrap_or_else(|| {
            panic!("WIRE.md row of kind {kind}: no `format` in backticks: {line}")
        });
        assert!(
            rows.insert(kind, format.to_string()).is_none(),
            "WIRE.md lists kind {kind} twice"
        );
    }
    rows
}

#[test]
fn wire_md_lists_every_kind_of_the_table_with_the_same_body_format() {
    let md = wire_md_formats();
    let table: BTreeMap<u8, String> = Kind::ALL
        .iter()
        .map(|&k| {
            let fixed = k.body_format().split(" +").next().unwrap().trim();
            (k as u8, fixed.to_string())
        })
        .collect();
    assert_eq!(md, table, "WIRE.md (left) and table.rs (right) disagree");
}
