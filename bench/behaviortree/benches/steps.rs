//! The workload with `behaviortree`: build + run (`behaviortree`) and run of an already built
//! tree (`behaviortree-prepared`), and heap allocations per plan.

use std::alloc::{GlobalAlloc, Layout, System};
use std::hint::black_box;
use std::sync::atomic::{AtomicU64, Ordering};

use criterion::{Criterion, criterion_group};
use psmpa_bench_behaviortree::{prepare, run_plan, run_prepared, workload};

/// `System`, counting calls of `alloc` and `realloc` (`alloc_zeroed` goes through `alloc`).
struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: forwards every call to `System` unchanged.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: the caller's guarantees, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's guarantees, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: the caller's guarantees, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made by `f`.
fn allocations<R>(f: impl FnOnce() -> R) -> (u64, R) {
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let r = f();
    (ALLOCATIONS.load(Ordering::Relaxed) - before, r)
}

fn report_allocations() {
    // Once before counting, for anything initialised on first use.
    assert_eq!(run_plan(), workload::EXPECTED_STEPS);
    let (n, steps) = allocations(run_plan);
    assert_eq!(steps, workload::EXPECTED_STEPS);
    println!("allocations per plan: behaviortree {n}");

    let mut p = prepare();
    assert_eq!(run_prepared(&mut p), workload::EXPECTED_STEPS);
    let (n, steps) = allocations(|| run_prepared(&mut p));
    assert_eq!(steps, workload::EXPECTED_STEPS);
    println!("allocations per plan: behaviortree-prepared {n}");
}

fn plan(c: &mut Criterion) {
    let mut group = c.benchmark_group("plan");
    assert_eq!(run_plan(), workload::EXPECTED_STEPS);
    group.bench_function("behaviortree", |b| b.iter(run_plan));

    let mut p = prepare();
    assert_eq!(run_prepared(&mut p), workload::EXPECTED_STEPS);
    group.bench_function("behaviortree-prepared", |b| {
        b.iter(|| run_prepared(black_box(&mut p)))
    });
    group.finish();
}

criterion_group!(benches, plan);

fn main() {
    report_allocations();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
