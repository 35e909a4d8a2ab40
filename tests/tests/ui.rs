//! Mistakes in a compiled mission are compile errors that name the field and the name; so is
//! a misuse of the API (an actuator without its safety stop, a second sampler or control loop
//! at once, the runtime's private entry points), and so is using one mission's robot, names or
//! keys with another: a platform for another mission, a typed view or a description with
//! another mission's names, a behaviour reading a sensor its action does not run beside, an
//! undeclared store key.

#[test]
fn mission_mistakes_fail_the_build() {
    let t = trybuild::TestCases::new();
    t.compile_fail("ui/*.rs");
}
