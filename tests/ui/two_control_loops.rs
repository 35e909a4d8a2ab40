// One control loop at a time: running the deciding side twice at once does not compile
// (one after the other does).
use psmpa_tests::tiny::TinyRuntime;

type Rt<'r> = TinyRuntime<'r>;

async fn twice(rt: &mut Rt<'_>) {
    let (_, mut deciding) = rt.split();
    let _ = psmpa_core::embassy_futures::join::join(deciding.run(), deciding.run()).await;
}

fn main() {
    let _ = twice;
}
