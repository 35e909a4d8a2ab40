//! Mistakes in a compiled mission are compile errors that name the field and the name.

#[test]
fn mission_mistakes_fail_the_build() {
    let t = trybuild::TestCases::new();
    t.compile_fail("ui/*.rs");
}
