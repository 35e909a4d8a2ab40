//! Any bytes given to the mission loader: a mission or an error that says what and where,
//! never a panic or a hang. A mission the simulated robot accepts compiles every plan.
#![no_main]

use libfuzzer_sys::fuzz_target;
use psmpa_core::mission::{AnyBehaviour, Loaded, load};
use psmpa_core::{Fsm, PlanId};
use psmpa_sim::robot::NaoRegistry;

fuzz_target!(|data: &[u8]| {
    let large: Result<Loaded<'_, (), (), 32, 64, 32, 16>, _> = load(data, &AnyBehaviour);
    if let Err(e) = &large {
        assert!(!e.to_string().is_empty());
    }
    let robot: Result<Loaded<'_, _, _, 4, 8, 4, 6>, _> = load(data, &NaoRegistry);
    match robot {
        Ok(m) => {
            for (i, plan) in m.mission.library.plans().iter().enumerate() {
                let id = PlanId::new(i).unwrap();
                assert!(Fsm::<6>::compile(id, plan, &m.mission.domain).is_ok());
            }
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
});
