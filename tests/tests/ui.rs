//! Mistakes in a compiled mission are compile errors that name the field and the name; so is
//! a misuse of the API (an actuator without its safety stop, swapped capacities, a second
//! sampler or control loop at once, the engine's private entry points).

#[test]
fn mission_mistakes_fail_the_build() {
    let t = trybuild::TestCases::new();
    t.compile_fail("ui/*.rs");
}
