// Both sides on one executor, twice at once on one runtime: does not compile (it reported
// `SensingStalled` at run time, which misled).
use psmpa_tests::tiny::TinyRuntime;

type Rt<'r> = TinyRuntime<'r>;

async fn twice(rt: &mut Rt<'_>) {
    let _ = psmpa_core::embassy_futures::join::join(rt.run_with_sensing(), rt.run_with_sensing())
        .await;
}

fn main() {
    let _ = twice;
}
