//! Nothing the cycle calls allocates: forward, every solution, seed 001's inverse, the
//! jacobian, the singularity check and joint velocities, for every registered kinematics,
//! on good poses and on every error path. A counting global allocator sees each allocation
//! of this (only) test's thread while counting is on.

use kinematics::{
    JointLimit, KinError, MAX_COORDS, MAX_JOINTS, REGISTRY, Solutions, cartesian_to_axes,
    joint_velocity,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
}

// SAFETY: every call is forwarded to the system allocator unchanged; the count is a side
// effect.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if COUNTING.with(Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: the caller's contract is the system allocator's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_cycles_computations_never_allocate() {
    let all: Vec<_> = REGISTRY
        .iter()
        .map(|e| e.build_example().expect("the example builds"))
        .collect();
    let tight = [JointLimit::new(-1.0, 1.0); MAX_JOINTS];
    let wide = [JointLimit::new(-400.0, 400.0); MAX_JOINTS];
    let values = [
        0.0,
        1.0,
        -30.0,
        45.0,
        90.0,
        200.0,
        1e9,
        f64::NAN,
        f64::INFINITY,
    ];

    COUNTING.with(|c| c.set(true));
    let mut outcomes = 0usize;
    for k in &all {
        for &a in &values {
            for &b in &values {
                let mut q = [10.0; MAX_JOINTS];
                q[0] = a;
                q[1] = b;
                let mut p = [0.0; MAX_COORDS];
                p[0] = a - 150.0;
                p[1] = b - 100.0;
                let mut s = Solutions::new();
                outcomes += usize::from(k.axes_to_cartesian(&q).is_ok());
                outcomes += usize::from(k.solutions(&p, &mut s).is_ok());
                outcomes += usize::from(k.is_singular(&q));
                outcomes += usize::from(k.jacobian(&q).is_ok());
                for limits in [&tight, &wide] {
                    let r: Result<_, KinError> = cartesian_to_axes(&**k, &p, &q, limits);
                    outcomes += usize::from(r.is_ok());
                }
                outcomes += usize::from(joint_velocity(&**k, &q, &p).is_ok());
            }
        }
    }
    COUNTING.with(|c| c.set(false));

    assert!(outcomes > 0);
    assert_eq!(
        ALLOCATIONS.load(Ordering::Relaxed),
        0,
        "allocations in the cycle's paths"
    );
}
