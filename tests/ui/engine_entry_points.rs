// The lower-level entry points are not public: the sides are the way in (`split`).
use psmpa_tests::tiny::TinyRuntime;

type Rt<'r> = TinyRuntime<'r>;

fn entry_points(rt: &Rt<'_>) {
    let _ = rt.sensing();
    let _ = rt.run();
    let _ = rt.establish_initial_model();
}

fn main() {
    let _ = entry_points;
}
