//! The checked-in `include/hbn.h` is what cbindgen generates from the current source.
//! Regenerate it with `HBN_BLESS=1 cargo test -p hbn-ffi --test header`.

use std::path::Path;

#[test]
fn header_is_up_to_date() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut fresh = Vec::new();
    bindings.write(&mut fresh);
    let fresh = String::from_utf8(fresh).expect("utf-8 header");
    let path = dir.join("include/hbn.h");
    if std::env::var_os("HBN_BLESS").is_some() {
        std::fs::write(&path, &fresh).expect("write include/hbn.h");
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        checked_in == fresh,
        "crates/hbn-ffi/include/hbn.h is stale: regenerate it with \
         `HBN_BLESS=1 cargo test -p hbn-ffi --test header` and commit it"
    );
}
