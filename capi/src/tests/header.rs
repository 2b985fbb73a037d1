//! The committed header `include/rkmpm.h` must equal what cbindgen generates from this crate
//! (`capi/src/`). `RKMPM_UPDATE_HEADER=1 cargo test --release -p rkmpm-capi header` rewrites it.

use std::path::Path;

#[test]
fn committed_header_is_up_to_date() {
    let root = env!("CARGO_MANIFEST_DIR");
    let config = cbindgen::Config::from_file(Path::new(root).join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(root)
        .with_config(config)
        .generate()
        .expect("cbindgen failed")
        .write(&mut generated);
    let generated = String::from_utf8(generated).unwrap();
    let path = Path::new(root).join("../include/rkmpm.h");
    if std::env::var_os("RKMPM_UPDATE_HEADER").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "include/rkmpm.h is out of date: run RKMPM_UPDATE_HEADER=1 cargo test --release -p rkmpm-capi header"
    );
    assert!(generated.contains("RKMPM_ABI_VERSION"));
    // Only the C API's own names: cbindgen reads this crate alone, so nothing else can leak here.
    for line in generated.lines() {
        if let Some(name) = line.strip_prefix("#define ") {
            assert!(
                name.starts_with("RKMPM_") || name.starts_with("RkmpmStatus_"),
                "{line}: not a C API name"
            );
        }
    }
}

/// The `RKMPM_*` integer constants of a text: `#define NAME VALUE` and enum lines `NAME = VALUE,`
/// of the C header, or `integer(...), parameter, public :: NAME = VALUE` of the Fortran module;
/// real constants too (`1.0e-4_c_double` in Fortran).
fn constants(text: &str) -> std::collections::BTreeMap<String, f64> {
    let mut out = std::collections::BTreeMap::new();
    for line in text.lines() {
        let line = line.trim();
        let line = line.strip_prefix("#define ").unwrap_or(line);
        let line = match line.split_once(":: ") {
            Some((decl, rest)) if decl.contains("parameter") => rest,
            _ => line,
        };
        let line = line.split('!').next().unwrap().trim().trim_end_matches(',');
        let mut words = line.split([' ', '=']).filter(|w| !w.is_empty());
        if let (Some(name), Some(value), None) = (words.next(), words.next(), words.next()) {
            let value = value.trim_end_matches("_c_double");
            if let (true, Ok(v)) = (name.starts_with("RKMPM_"), value.parse::<f64>()) {
                assert!(out.insert(name.to_string(), v).is_none(), "{name} twice");
            }
        }
    }
    out
}

/// A file of the repository, by its path from the repository's root.
fn read(path: &str) -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)).unwrap()
}

/// The Fortran module spells every constant of the C header with the header's value, and has
/// no other constants than the sides (C passes -1 and +1 as numbers) and its own ABI version.
#[test]
fn fortran_constants_match_the_header() {
    let c = constants(&read("include/rkmpm.h"));
    let f = constants(&read("bindings/fortran/rkmpm.f90"));
    // The ABI version, 16 statuses and 26 option and field codes.
    assert!(c.len() >= 43, "parsed only {} header constants", c.len());
    for (name, value) in &c {
        let fname = match name.as_str() {
            "RKMPM_ABI_VERSION" => "RKMPM_BINDING_ABI_VERSION",
            n => n,
        };
        assert_eq!(
            f.get(fname),
            Some(value),
            "{fname} in bindings/fortran/rkmpm.f90"
        );
    }
    let extra: Vec<_> = f
        .keys()
        .filter(|n| !c.contains_key(*n))
        .map(String::as_str)
        .collect();
    assert_eq!(
        extra,
        [
            "RKMPM_BINDING_ABI_VERSION",
            "RKMPM_SIDE_HIGH",
            "RKMPM_SIDE_LOW"
        ]
    );
}

/// Each family of C codes is 0, 1, ..., n − 1 and is exactly the codes its kind accepts
/// (`rkmpm::options`), so no option lacks a C spelling.
#[test]
fn c_codes_cover_every_kind() {
    use rkmpm::options::{IntegrationKind, Scheme, ShapeKind, TransferKind, WallKind};
    use rkmpm::Field;
    let c = constants(&read("include/rkmpm.h"));
    let accepts: [(&str, &dyn Fn(u32) -> bool); 6] = [
        ("RKMPM_SHAPE_", &|k| ShapeKind::try_from(k).is_ok()),
        ("RKMPM_INTEGRATION_", &|k| {
            IntegrationKind::try_from(k).is_ok()
        }),
        ("RKMPM_TRANSFER_", &|k| TransferKind::try_from(k).is_ok()),
        ("RKMPM_SCHEME_", &|k| Scheme::try_from(k).is_ok()),
        ("RKMPM_BOUNDARY_", &|k| WallKind::try_from(k).is_ok()),
        ("RKMPM_FIELD_", &|k| Field::try_from(k).is_ok()),
    ];
    for (prefix, accepts) in accepts {
        let mut codes: Vec<i64> = c
            .iter()
            .filter(|(n, _)| n.starts_with(prefix))
            .map(|(_, &v)| v as i64)
            .collect();
        codes.sort();
        let n = codes.len() as u32;
        assert!(n >= 2, "{prefix}: {codes:?}");
        assert_eq!(codes, (0..n as i64).collect::<Vec<_>>(), "{prefix}");
        assert!((0..n).all(accepts), "{prefix}");
        assert!(!accepts(n), "{prefix}{n} is accepted but has no C name");
    }
}
