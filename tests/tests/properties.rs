//! Properties of the core, checked on generated inputs (proptest).

use std::collections::{BTreeSet, HashMap, HashSet};

use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::Instant;
use proptest::prelude::*;
use psmpa_core::planner::{Planner, Strategy};
use psmpa_core::{
    ActionId, ActuatorAction, DataStore, Domain, FactId, FactSet, Fsm, Key, PlanId, SensorAction,
    SensorMode, StoreAccess, Target, Value,
};

fn facts(bits: u64, n: u32) -> FactSet {
    FactSet::from_bits(bits & ((1u64 << n) - 1))
}

proptest! {
    /// Algorithm 2, against an oracle written from the paper, not from the core: the facts
    /// are names, `per(s)` and `pre(a)` are `BTreeSet`s of names drawn as lists, and action
    /// state `δᵢ` gets the parallel sensor `s_k` exactly when `per(s_k) ⊆ pre(aᵢ)` (line 11)
    /// and `per(s_k)` is not empty (the runtime's reading: a sensor that perceives nothing is
    /// no one's). The transitions chain the body in order (lines 7 to 10).
    #[test]
    fn fsm_states_run_exactly_the_sensors_their_precondition_needs(
        pers in prop::collection::vec(prop::collection::vec(0usize..12, 0..4), 0..8),
        pres in prop::collection::vec(prop::collection::vec(0usize..12, 0..8), 1..8),
        body in prop::collection::vec(0usize..8, 1..8),
    ) {
        let fact_names: Vec<String> = (0..12).map(|i| format!("f{i}")).collect();
        let named = |ids: &Vec<usize>| -> BTreeSet<&str> {
            ids.iter().map(|i| fact_names[*i].as_str()).collect()
        };
        let sensors: Vec<(String, BTreeSet<&str>)> =
            pers.iter().enumerate().map(|(i, p)| (format!("s{i}"), named(p))).collect();
        let actions: Vec<(String, BTreeSet<&str>)> =
            pres.iter().enumerate().map(|(i, p)| (format!("a{i}"), named(p))).collect();
        let body: Vec<usize> = body.iter().map(|b| b % actions.len()).collect();

        // The oracle: for each step of the body, the names of its parallel sensors.
        let expected: Vec<BTreeSet<&str>> = body
            .iter()
            .map(|a| {
                let pre = &actions[*a].1;
                sensors
                    .iter()
                    .filter(|(_, per)| !per.is_empty() && per.is_subset(pre))
                    .map(|(name, _)| name.as_str())
                    .collect()
            })
            .collect();

        // The same domain, given to the core by name.
        let mut d: Domain<'_, 8, 8> = Domain::new();
        let ids: HashMap<&str, FactId> =
            fact_names.iter().map(|n| (n.as_str(), d.add_fact(n).unwrap())).collect();
        let set = |names: &BTreeSet<&str>| -> FactSet { names.iter().map(|n| ids[n]).collect() };
        let ev = d.add_event("e").unwrap();
        for (name, per) in &sensors {
            d.add_sensor(SensorAction::new(name, set(per), SensorMode::OneShot)).unwrap();
        }
        for (name, pre) in &actions {
            d.add_action(ActuatorAction::new(name, set(pre), FactSet::EMPTY, FactSet::EMPTY)).unwrap();
        }
        let body_ids: Vec<ActionId> = body.iter().map(|a| ActionId::new(*a).unwrap()).collect();
        let _ = ev;
        let fsm = Fsm::compile(PlanId::new(0).unwrap(), &body_ids, d.actions()).unwrap();

        let states: Vec<_> = fsm.states(d.actions(), d.sensors()).collect();
        prop_assert_eq!(states.len(), body.len());
        for (i, state) in states.iter().enumerate() {
            let action = d.action(state.action).unwrap().name;
            prop_assert_eq!(action, actions[body[i]].0.as_str());
            let got: BTreeSet<&str> =
                state.sensors.iter().map(|s| d.sensor(s).unwrap().name).collect();
            prop_assert_eq!(&got, &expected[i], "state {} ({})", i, action);
            let next = if i + 1 == body.len() { Target::Done } else { Target::State(i as u8 + 1) };
            prop_assert_eq!(state.on_success, next);
            prop_assert_eq!(state.on_failure, Target::Failed);
        }
    }

    /// τ' = add ∪ (τ \ del), fact by fact, as sets.
    #[test]
    fn effects_follow_set_semantics(state in any::<u64>(), add in any::<u64>(), del in any::<u64>()) {
        let as_set = |bits: u64| -> HashSet<usize> { (0..64).filter(|i| bits >> i & 1 == 1).collect() };
        let result = FactSet::from_bits(state).apply(FactSet::from_bits(add), FactSet::from_bits(del));
        let expected: HashSet<usize> = as_set(add).union(&as_set(state).difference(&as_set(del)).copied().collect()).copied().collect();
        let got: HashSet<usize> = result.iter().map(FactId::index).collect();
        prop_assert_eq!(got, expected);
    }

    /// Whatever the sequence of puts, an accepted value stays readable until its key is
    /// written again, a refused put changes nothing, and refusals happen only when full.
    #[test]
    fn the_store_never_loses_an_accepted_value(ops in prop::collection::vec((0u8..24, any::<i32>()), 0..200)) {
        let store: DataStore<NoopRawMutex, 8> = DataStore::new();
        let mut model: HashMap<u8, (i32, u64)> = HashMap::new();
        for (t, (key, value)) in ops.into_iter().enumerate() {
            let at = Instant::from_ticks(t as u64);
            match store.put(Key(key), Value::Int(value), at) {
                Ok(()) => {
                    model.insert(key, (value, t as u64));
                }
                Err(full) => {
                    prop_assert_eq!(model.len(), 8);
                    prop_assert!(!model.contains_key(&key));
                    prop_assert_eq!(full.value, Value::Int(value));
                }
            }
            prop_assert_eq!(store.len(), model.len());
        }
        for key in 0u8..24 {
            let expected = model.get(&key).map(|&(v, t)| (Value::Int(v), Instant::from_ticks(t)));
            prop_assert_eq!(store.get(Key(key)).map(|e| (e.value, e.at)), expected);
        }
    }

    /// The planner is sound (its plans run and reach the goal) and, breadth-first or A* with
    /// h_max, optimal: both find plans of the same length, or both find none.
    #[test]
    fn plans_are_sound_and_shortest(
        actions in prop::collection::vec((any::<u16>(), any::<u16>(), any::<u16>()), 1..10),
        init in any::<u16>(),
        goal in any::<u16>(),
    ) {
        const N: u32 = 8;
        let names: Vec<String> = (0..N).map(|i| format!("f{i}")).collect();
        let action_names: Vec<String> = (0..actions.len()).map(|i| format!("a{i}")).collect();
        let mut d: Domain<'_, 1, 16> = Domain::new();
        for n in &names {
            d.add_fact(n).unwrap();
        }
        for (n, (pre, add, del)) in action_names.iter().zip(&actions) {
            d.add_action(ActuatorAction::new(n, facts(u64::from(*pre) & 0x0f, N), facts(u64::from(*add), N), facts(u64::from(*del), N))).unwrap();
        }
        let (init, goal) = (facts(u64::from(init), N), facts(u64::from(goal) & 0x33, N));
        let bfs = Planner::<512>::new(Strategy::BreadthFirst).plan::<32>(d.actions(), init, goal);
        let astar = Planner::<512>::new(Strategy::AStar(psmpa_core::planner::Heuristic::Max)).plan::<32>(d.actions(), init, goal);
        match (&bfs, &astar) {
            (Ok(a), Ok(b)) => {
                prop_assert_eq!(a.body.len(), b.body.len());
                for found in [a, b] {
                    let end = found.body.iter().try_fold(init, |s, a| {
                        let a = d.action(*a).unwrap();
                        a.pre.is_subset(s).then(|| s.apply(a.add, a.del))
                    });
                    prop_assert!(end.is_some_and(|e| goal.is_subset(e)));
                }
            }
            (Err(psmpa_core::planner::PlanningError::Unsolvable { .. }), Err(psmpa_core::planner::PlanningError::Unsolvable { .. })) => {}
            other => prop_assert!(false, "breadth-first and A* disagree: {:?}", other),
        }
    }
}
