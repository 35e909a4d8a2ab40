//! The README's quickstart is `tests/quickstart.rs`, word for word: the test that runs is the
//! text a reader copies.

#[test]
fn the_readme_quickstart_is_the_compiled_test() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
    let test = std::fs::read_to_string(format!("{root}/testkit/tests/quickstart.rs")).unwrap();
    let (_, after) = readme.split_once("<!-- quickstart:start -->").unwrap();
    let (block, _) = after.split_once("<!-- quickstart:end -->").unwrap();
    let code = block
        .trim()
        .strip_prefix("```rust")
        .and_then(|b| b.strip_suffix("```"))
        .expect("the quickstart is one ```rust block");
    assert_eq!(
        code.trim(),
        test.trim(),
        "README.md's quickstart differs from testkit/tests/quickstart.rs: copy the file in"
    );
}

/// The crates a reader must add to run the quickstart: every crate the test `use`s is in the
/// README's `Cargo.toml` block (a `use` of a crate missing there does not compile outside).
#[test]
fn the_readme_quickstart_names_every_crate_it_uses() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
    let test = std::fs::read_to_string(format!("{root}/testkit/tests/quickstart.rs")).unwrap();
    let (_, after) = readme.split_once("<!-- quickstart-deps:start -->").unwrap();
    let (toml, _) = after.split_once("<!-- quickstart-deps:end -->").unwrap();
    let listed: Vec<String> = toml
        .lines()
        .filter_map(|l| {
            l.split_once('=')
                .map(|(name, _)| name.trim().replace('-', "_"))
        })
        .collect();
    let used: Vec<&str> = test
        .lines()
        .filter_map(|l| l.strip_prefix("use "))
        .filter_map(|l| l.split("::").next())
        .filter(|c| !matches!(*c, "std" | "core" | "alloc" | "crate" | "self" | "super"))
        .collect();
    assert!(
        !used.is_empty(),
        "the quickstart uses no crate: the parse is wrong"
    );
    for krate in used {
        assert!(
            listed.iter().any(|l| l == krate),
            "the quickstart uses `{krate}`, which README.md's Cargo.toml block does not add"
        );
    }
}
