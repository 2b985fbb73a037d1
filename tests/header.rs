//! The committed header `include/rkmpm.h` must equal what cbindgen generates from `src/ffi/`.
//! `RKMPM_UPDATE_HEADER=1 cargo test --test header` rewrites it.

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
    let path = Path::new(root).join("include/rkmpm.h");
    if std::env::var_os("RKMPM_UPDATE_HEADER").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "include/rkmpm.h is out of date: run RKMPM_UPDATE_HEADER=1 cargo test --test header"
    );
    assert!(generated.contains("RKMPM_ABI_VERSION"));
}
