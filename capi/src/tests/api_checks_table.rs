//! `docs/C_API_CHECKS.md` (what every C entry point checks) and `examples/c/api_checks.c` (a C
//! test per row) must not drift apart: the same row ids on both sides with the same statuses,
//! status numbers as in `capi/src/status.rs`, and a table for every exported function of
//! `capi/src/lib.rs`. Reads files only; the C driver itself runs under CTest (`c_api_checks`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The "status" of a row whose function returns no status (`NO_STATUS` in the C driver, `—` in
/// the table).
const NO_STATUS: &str = "NO_STATUS";

/// A file of the repository, by its path from the repository's root.
fn read(relative: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(relative);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

/// Row id prefix of an exported function: the name without `rkmpm_sim_` (or `rkmpm_`).
fn short_name(function: &str) -> &str {
    function
        .strip_prefix("rkmpm_sim_")
        .or_else(|| function.strip_prefix("rkmpm_"))
        .unwrap_or(function)
}

fn is_row_id(s: &str) -> bool {
    let mut parts = s.split('.');
    let ok = |p: Option<&str>| {
        p.is_some_and(|p| {
            !p.is_empty()
                && p.chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        })
    };
    ok(parts.next()) && ok(parts.next()) && parts.next().is_none()
}

/// The first `RKMPM_OK` / `RKMPM_ERR_*` name in `text` and the text after it.
fn status_name(text: &str) -> Option<(&str, &str)> {
    let start = text.find("RKMPM_")?;
    let rest = &text[start..];
    let end = rest
        .find(|c: char| !(c.is_ascii_uppercase() || c == '_'))
        .unwrap_or(rest.len());
    Some((&rest[..end], &rest[end..]))
}

/// Exported functions of the C API (`pub [unsafe] extern "C" fn rkmpm_*`) and whether each
/// returns an `RkmpmStatus`.
fn exported_functions() -> BTreeMap<String, bool> {
    let source = read("capi/src/lib.rs");
    let mut functions = BTreeMap::new();
    for (at, _) in source.match_indices("extern \"C\" fn rkmpm_") {
        let line_start = source[..at].rfind('\n').map_or(0, |k| k + 1);
        let head = source[line_start..at].trim();
        if head != "pub" && head != "pub unsafe" {
            continue;
        }
        let name_start = at + "extern \"C\" fn ".len();
        let name_end = name_start + source[name_start..].find('(').expect("(");
        let signature_end = name_start + source[name_start..].find('{').expect("{");
        let returns_status = source[name_end..signature_end].contains("-> RkmpmStatus");
        let name = source[name_start..name_end].to_string();
        assert!(
            functions.insert(name.clone(), returns_status).is_none(),
            "{name} exported twice"
        );
    }
    functions
}

/// `RKMPM_* = n` of `capi/src/status.rs`.
fn status_numbers() -> BTreeMap<String, i64> {
    let mut numbers = BTreeMap::new();
    for line in read("capi/src/status.rs").lines() {
        let line = line.trim();
        if let Some((name, value)) = line.split_once(" = ") {
            if name.starts_with("RKMPM_") && !name.contains(' ') {
                let value = value.trim_end_matches(',');
                if let Ok(n) = value.parse() {
                    numbers.insert(name.to_string(), n);
                }
            }
        }
    }
    assert!(
        numbers.get("RKMPM_OK") == Some(&0),
        "status.rs: no RKMPM_OK = 0"
    );
    numbers
}

/// A row of the table.
struct DocRow {
    status: String,
    /// The function of the `###` heading the row sits under.
    section: String,
}

/// The tables of the document: rows by id, and the functions that have a heading.
fn doc_rows(numbers: &BTreeMap<String, i64>) -> (BTreeMap<String, DocRow>, BTreeSet<String>) {
    let doc = read("docs/C_API_CHECKS.md");
    let mut rows = BTreeMap::new();
    let mut sections = BTreeSet::new();
    let mut section: Option<String> = None;
    for (k, line) in doc.lines().enumerate() {
        let n = k + 1;
        if line.starts_with("## ") {
            section = None;
        }
        if let Some(title) = line.strip_prefix("### ") {
            let name = title.trim().trim_matches('`');
            assert!(
                name.starts_with("rkmpm_") && !name.contains(' '),
                "docs/C_API_CHECKS.md:{n}: a table heading must be a function name in backticks: {line}"
            );
            assert!(
                sections.insert(name.to_string()),
                "docs/C_API_CHECKS.md:{n}: {name} has two tables"
            );
            section = Some(name.to_string());
            continue;
        }
        if !line.starts_with("| `") {
            continue;
        }
        let cells: Vec<&str> = line
            .trim()
            .trim_matches('|')
            .split('|')
            .map(str::trim)
            .collect();
        let id = cells[0].trim_matches('`');
        if !is_row_id(id) {
            continue;
        }
        assert_eq!(
            cells.len(),
            4,
            "docs/C_API_CHECKS.md:{n}: a row has 4 cells (id, input, status, unchanged): {line}"
        );
        let Some(section) = section.clone() else {
            panic!("docs/C_API_CHECKS.md:{n}: row {id} is not under a function's heading");
        };
        let status = match status_name(cells[2]) {
            Some((name, after)) => {
                let number = numbers.get(name).unwrap_or_else(|| {
                    panic!("docs/C_API_CHECKS.md:{n}: {id}: {name} is not a status of status.rs")
                });
                let expected = format!("` ({number})");
                assert!(
                    after.starts_with(&expected),
                    "docs/C_API_CHECKS.md:{n}: {id}: write the status as `{name}` ({number})"
                );
                name.to_string()
            }
            None => {
                assert!(
                    cells[2].starts_with('—'),
                    "docs/C_API_CHECKS.md:{n}: {id}: the status is an RKMPM_* name or — (none)"
                );
                NO_STATUS.to_string()
            }
        };
        let previous = rows.insert(id.to_string(), DocRow { status, section });
        assert!(
            previous.is_none(),
            "docs/C_API_CHECKS.md:{n}: row {id} appears twice"
        );
    }
    (rows, sections)
}

/// `ROW("<id>", <status>)` of the C driver: status by id.
fn c_rows() -> BTreeMap<String, String> {
    let source = read("examples/c/api_checks.c");
    let mut rows = BTreeMap::new();
    for (at, _) in source.match_indices("ROW(\"") {
        let rest = &source[at + "ROW(\"".len()..];
        let id = &rest[..rest.find('"').expect("closing quote")];
        let rest = rest[id.len() + 1..].trim_start();
        let rest = rest
            .strip_prefix(',')
            .unwrap_or_else(|| panic!("api_checks.c: ROW(\"{id}\" without a status"))
            .trim_start();
        let status = &rest[..rest.find(')').expect(")")];
        assert!(
            is_row_id(id),
            "api_checks.c: {id:?} is not a row id (<function>.<case>)"
        );
        assert!(
            status == NO_STATUS || status.starts_with("RKMPM_"),
            "api_checks.c: ROW(\"{id}\", {status}): the status is RKMPM_* or NO_STATUS"
        );
        assert!(
            rows.insert(id.to_string(), status.trim().to_string())
                .is_none(),
            "api_checks.c: row {id} appears twice"
        );
    }
    rows
}

#[test]
fn table_and_c_driver_have_the_same_rows_and_statuses() {
    let numbers = status_numbers();
    let (doc, _) = doc_rows(&numbers);
    let c = c_rows();
    let doc_ids: BTreeSet<&String> = doc.keys().collect();
    let c_ids: BTreeSet<&String> = c.keys().collect();
    let only_doc: Vec<_> = doc_ids.difference(&c_ids).collect();
    let only_c: Vec<_> = c_ids.difference(&doc_ids).collect();
    assert!(
        only_doc.is_empty() && only_c.is_empty(),
        "rows without a C test (in docs/C_API_CHECKS.md only): {only_doc:?}\n\
         rows not in the table (in examples/c/api_checks.c only): {only_c:?}"
    );
    let differ: Vec<String> = doc
        .iter()
        .filter(|(id, row)| c[*id] != row.status)
        .map(|(id, row)| format!("{id}: table {}, C {}", row.status, c[id]))
        .collect();
    assert!(differ.is_empty(), "statuses differ: {differ:#?}");
    assert!(doc.len() > 100, "only {} rows found", doc.len());
}

#[test]
fn every_exported_function_has_a_table_with_rows() {
    let numbers = status_numbers();
    let (doc, sections) = doc_rows(&numbers);
    let functions = exported_functions();
    assert!(
        functions.len() >= 34,
        "found only {} exported functions in capi/src/lib.rs",
        functions.len()
    );
    let mut problems = Vec::new();
    for (function, &returns_status) in &functions {
        if !sections.contains(function) {
            problems.push(format!("{function}: no `### \\`{function}\\`` table"));
        }
        let prefix = short_name(function);
        let rows: Vec<(&String, &DocRow)> = doc
            .iter()
            .filter(|(id, _)| id.split('.').next() == Some(prefix))
            .collect();
        if rows.is_empty() {
            problems.push(format!("{function}: no row `{prefix}.<case>`"));
        }
        for (id, row) in rows {
            if row.section != *function {
                problems.push(format!("{id} is under the table of {}", row.section));
            }
            if returns_status == (row.status == NO_STATUS) {
                problems.push(format!(
                    "{id}: {function} {} a status, the row says {}",
                    if returns_status {
                        "returns"
                    } else {
                        "returns no"
                    },
                    row.status
                ));
            }
        }
    }
    for section in &sections {
        if !functions.contains_key(section) {
            problems.push(format!(
                "table {section}: not an exported function of capi/src/lib.rs"
            ));
        }
    }
    for (id, row) in &doc {
        if !functions.contains_key(&row.section)
            || !id.starts_with(&format!("{}.", short_name(&row.section)))
        {
            problems.push(format!(
                "{id}: the id does not name the function of its table ({})",
                row.section
            ));
        }
    }
    assert!(problems.is_empty(), "{problems:#?}");
}
