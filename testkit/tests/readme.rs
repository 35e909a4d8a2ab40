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
