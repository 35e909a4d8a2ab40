// The sensing side is handed out once: a second split while the first side runs, for a second
// sampler of every sensor, does not compile.
use psmpa_core::Config;
use psmpa_tests::tiny::TinyRuntime;

type Rt<'r> = TinyRuntime<'r>;

fn twice(rt: &mut Rt<'_>) {
    let (sensing, _) = rt.split();
    let (again, _) = rt.split();
    drop((sensing, again));
}

fn main() {
    let _ = (twice, Config::default());
}
