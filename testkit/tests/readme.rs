//! The README's quickstart is `tests/hello.json` and `tests/quickstart.rs`, word for word: the
//! test that runs is the text a reader copies.

/// The one fenced block of language `lang` between the README's `<!-- {marker}:start -->` and
/// `<!-- {marker}:end -->`.
fn block(readme: &str, marker: &str, lang: &str) -> String {
    let (_, after) = readme
        .split_once(&format!("<!-- {marker}:start -->"))
        .unwrap();
    let (block, _) = after.split_once(&format!("<!-- {marker}:end -->")).unwrap();
    block
        .trim()
        .strip_prefix(&format!("```{lang}"))
        .and_then(|b| b.strip_suffix("```"))
        .unwrap_or_else(|| panic!("{marker} is one ```{lang} block"))
        .trim()
        .to_owned()
}

#[test]
fn the_readme_quickstart_is_the_compiled_test_and_its_mission() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    let readme = std::fs::read_to_string(format!("{root}/README.md")).unwrap();
    for (marker, lang, file) in [
        ("quickstart-mission", "json", "testkit/tests/hello.json"),
        ("quickstart", "rust", "testkit/tests/quickstart.rs"),
    ] {
        let text = std::fs::read_to_string(format!("{root}/{file}")).unwrap();
        assert_eq!(
            block(&readme, marker, lang),
            text.trim(),
            "README.md's {marker} block differs from {file}: copy the file in"
        );
    }
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
